//! Arguments of `frictl demo`.

use std::path::PathBuf;

use super::experiment::RobotSel;

/// Arguments of `frictl demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory.
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// The paper's sizes (full protocol, 268×215 network, H 20, 350 epochs, lr 7.6e-4, λ 0.164,
    /// dropout 0.07; takes much longer).
    #[arg(long, conflicts_with = "quick")]
    pub full: bool,
    /// Tiny settings (one starting pose, small network, few epochs, coarse K_p search): a smoke
    /// run of the whole chain in a few minutes (used by the end-to-end test).
    #[arg(long)]
    pub quick: bool,
    /// Seed of the training acquisition (the test run uses seed + 100) and of the experiments.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Skip the closed-loop experiments.
    #[arg(long)]
    pub no_experiments: bool,
    /// Label with causal filters (`frictl preprocess --causal`: forward Butterworth and Kalman
    /// filter), so the PINN trains on signals like the ones frictiond sees at run time.
    #[arg(long)]
    pub causal: bool,
    /// Keep the reflected rotor inertia J_eq·φ̈ in the label (the paper's label; by default it is
    /// subtracted with the simulator's r²·J_m, see the module doc).
    #[arg(long)]
    pub with_rotor_inertia: bool,
    /// On-policy (DAgger) rounds before the closed-loop experiments (default: 1; `--quick` 0,
    /// `--full` 2; 0 = train on the open-loop protocol only). Each round finds the current PINN's
    /// minimum K_p, records varied closed-loop runs with it compensating through the real processes
    /// (`frictl experiment record`), labels them (`frictl preprocess`) and continues training from
    /// the current model on the union of every dataset so far (`frictl train --init`). With
    /// `--robot leg` the rounds run on the coupled leg (the knee and the ankle roll tested, the rest
    /// holding; labels from the whole leg's state).
    #[arg(long)]
    pub onpolicy_rounds: Option<u32>,
    /// Distil each joint's final PINN into a small student (the pipeline's distillation stage: a
    /// 32×32×32 int16 student, or with `--quick` the teacher pruned to 16×16, trained on the
    /// teacher's output over its training datasets), gated on the unseen test run at 1.05× the
    /// teacher's RMSE, overall and per |ṡ| band; the
    /// report's `joints.JOINT.models.pinn_distilled` has both RMSEs and inference times. The
    /// experiments keep using the teacher.
    #[arg(long)]
    pub distill: bool,
    /// `torque`: the chain on a torque-sensed joint instead (no motor encoder; import, training on two
    /// speed runs, evaluation on the held-out third; no closed-loop experiments), see `demo::torque`.
    #[arg(long, value_enum, default_value_t = DemoSensor::MotorEncoder)]
    pub sensor: DemoSensor,
    /// `leg`: the coupled six-joint ergoCub left leg instead of two independent joints (every joint
    /// excited at once, labels from the whole leg's state, a model per joint, one six-joint
    /// frictiond config, the closed loop on the knee and the ankle roll), see `demo::leg`.
    #[arg(long, value_enum, default_value_t = RobotSel::Joints)]
    pub robot: RobotSel,
}

/// Which joint the demo runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum DemoSensor {
    /// The robot's joints (motor and joint encoders, current): the paper's chain and the experiments.
    MotorEncoder,
    /// A torque-sensed joint (joint torque sensor, no motor encoder): `demo::torque`.
    Torque,
}

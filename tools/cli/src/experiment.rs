//! Arguments of `frictl experiment`.

use std::path::PathBuf;

/// Which experiment.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Kind {
    /// Sine tracking at `--kp` for every model.
    Track,
    /// Lowest K_p per model that tracks the sine within the criterion (bisection on a log scale).
    MinKp,
    /// Hold, external torque pulse, release: with `--kp` at that gain for all models; without,
    /// at each model's own minimum K_p and at the PINN's for all (runs the K_p search first).
    Disturbance,
    /// min-kp, then disturbance at the own and at the PINN's K_p, and tracking at the PINN's K_p.
    All,
    /// On-policy recording (DAgger): varied sine-tracking and disturbance runs around `--kp` with
    /// one model per joint compensating, written as acquisition logs `--out/<joint>_onpolicy.csv`
    /// (+ `.json`) for `frictl preprocess` (see `frictionless_experiment::onpolicy`), and
    /// `--out/record.json` with each run's τ̂_F/kfc error against the true friction.
    Record,
}

/// Which plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RobotSel {
    /// The two independent single-joint presets (knee, ankle roll).
    Joints,
    /// The coupled six-joint ergoCub leg (`sim serve --preset leg`), whole-leg computed torque.
    Leg,
}

/// Which joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum JointSel {
    /// The knee (index 0).
    Knee,
    /// The ankle roll (index 1).
    #[value(name = "ankle_roll", alias = "ankle-roll")]
    AnkleRoll,
    /// Both (sharing trials, unless `--jobs` leaves a core idle).
    Both,
}

/// Friction model names on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ModelSel {
    /// No compensation.
    None,
    /// Coulomb–viscous (`--cv`).
    Cv,
    /// Stribeck–Coulomb–viscous (`--scv`).
    Scv,
    /// PINN (`--pinn`).
    Pinn,
    /// Diagnostic bound "oracle (true friction)": frictiond runs no model and the controller adds
    /// frictiond's law applied to the plant's true friction (kfc, clip, LPF) to τ_des. Lockstep only;
    /// not a model a robot can run.
    Oracle,
}

/// Arguments of `frictl experiment`.
#[derive(clap::Args, Debug, serde::Serialize)]
pub struct Args {
    /// Experiment.
    #[arg(value_enum)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub kind: Kind,
    /// Joints.
    #[arg(long, value_enum, default_value_t = JointSel::Both)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub joint: JointSel,
    /// Plant: the single joints, or the leg (`all` only: min-K_p and disturbance on the knee and
    /// the ankle roll while the rest of the leg holds or moves; writes leg-tables.md and
    /// leg-report.json).
    #[arg(long, value_enum, default_value_t = RobotSel::Joints)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub robot: RobotSel,
    /// `--robot leg`: a compensation per frictiond config, `LABEL=FILE`, comma-separated (each leg
    /// joint runs the model of the config's joint of the same name, none if not listed; e.g. the
    /// config `frictl robot run` writes; a config naming no leg joint is refused). Each label is one
    /// row of the report: non-empty, given once, not `none` (always runs) or `oracle` (`--model
    /// oracle` adds it). Only with `--robot leg`, which takes no `--joint`, `--cv`, `--scv`,
    /// `--pinn` and no `--model` but `oracle`.
    #[arg(long, value_delimiter = ',')]
    pub leg_config: Vec<String>,
    /// `--robot leg`: the joints not under test move on sines of this amplitude [rad] at 0.3 Hz
    /// instead of holding their pose.
    #[arg(long)]
    pub rest_sine_rad: Option<f64>,
    /// `--robot leg`: K_p of the joints not under test [1/s²] (with the paper's M = link inertia,
    /// the distal joints need a high gain to hold while the tested joint is disturbed).
    #[arg(long, default_value_t = 5000.0)]
    pub rest_kp: f64,
    /// Models, comma-separated (default: none plus every model whose file is given).
    #[arg(long, value_enum, value_delimiter = ',')]
    #[serde(serialize_with = "super::stage::as_opt_value_enums")]
    pub model: Option<Vec<ModelSel>>,
    /// CV fit JSON from `frictl fit cv --json`: `knee=F.json,ankle_roll=G.json` (or one file with
    /// one joint).
    #[arg(long)]
    pub cv: Option<String>,
    /// SCV fit JSON from `frictl fit scv --json`, per joint like `--cv`.
    #[arg(long)]
    pub scv: Option<String>,
    /// PINN weight files: `knee=F.fwt,ankle_roll=G.fwt`.
    #[arg(long)]
    pub pinn: Option<String>,
    /// K_p [1/s²] for `track` and for `disturbance --kp`: one value or `knee=30,ankle_roll=550`
    /// (default for `track`: the paper's PINN gains, knee 30, ankle roll 550).
    #[arg(long)]
    pub kp: Option<String>,
    /// Lockstep (default): one tick per message, fast and deterministic.
    #[arg(long, conflicts_with = "realtime")]
    pub lockstep: bool,
    /// Real time: the plant at 1 kHz wall clock, frictiond on its clock.
    #[arg(long)]
    pub realtime: bool,
    /// Output directory (tables.md, report.json, traces/*.csv, plots).
    #[arg(long, default_value = "experiment-out")]
    pub out: PathBuf,
    /// Also write the JSON report here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Plant seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Plant parameter override (`--set plant.f_s0_nm=5`), applied to both presets; `JOINT:` in front
    /// applies it to one (`--set ankle_roll:plant.t0_min_c=31`).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// `record`: runs per joint (at most 6: sines of other amplitudes, frequencies and gains than
    /// the test sine, then pulses of both signs).
    #[arg(long, default_value_t = 6)]
    pub record_runs: usize,
    /// Tracking criterion: RMSE ≤ this fraction of the sine amplitude.
    #[arg(long, default_value_t = 0.1)]
    pub criterion_frac: f64,
    /// Sine periods per tracking trial.
    #[arg(long, default_value_t = 3.0)]
    pub periods: f64,
    /// Periods excluded from the evaluation (start-up).
    #[arg(long, default_value_t = 1.0)]
    pub skip_periods: f64,
    /// Bisection halvings of the K_p search.
    #[arg(long, default_value_t = 7)]
    pub iterations: u32,
    /// K_p search range per joint, `knee=3:3000,ankle_roll=30:100000` (the default).
    #[arg(long)]
    pub kp_range: Option<String>,
    /// Disturbance pulse torque [Nm] per joint, `knee=15,ankle_roll=5` (the default).
    #[arg(long)]
    pub pulse_nm: Option<String>,
    /// Disturbance pulse duration [s].
    #[arg(long, default_value_t = 1.0)]
    pub pulse_s: f64,
    /// Hold time before the pulse [s].
    #[arg(long, default_value_t = 1.0)]
    pub hold_s: f64,
    /// Observation time after the release [s].
    #[arg(long, default_value_t = 3.0)]
    pub after_release_s: f64,
    /// No per-trial progress lines.
    #[arg(long)]
    pub quiet: bool,
    /// Do not write PNG plots.
    #[arg(long)]
    pub no_plots: bool,
    /// The PINN's Δθ offset θ_off in frictiond (`delta_theta_offset_motor_rad`), one value or
    /// `knee=V,ankle_roll=W`: a number [motor rad] is fixed across enables — use the value of the
    /// train report (`datasets[].delta_theta_offset_motor_rad`; 0 for logs of the virtual joints,
    /// whose encoders read θ = r·φ, so Δθ = r·s − θ is the absolute deflection); `enable` latches
    /// Δθ = 0 at every enable, whatever torque the transmission holds then (only right for a
    /// network trained with `--delta-theta-offset chunk`).
    #[arg(long, default_value = "0")]
    pub pinn_delta_theta_offset: String,
    /// Friction compensation gain kfc of every model, one value or `knee=A,ankle_roll=B`
    /// (default: the shipped `config/ankle_knee.toml`, knee 0.85, ankle roll 0.7; the paper-era
    /// ergoCub SN002 config used 1).
    #[arg(long)]
    pub kfc: Option<String>,
    /// Low-pass on τ̂_F in frictiond (and on the oracle's term): `off` (no `lpf`), a cut-off [Hz]
    /// (Butterworth of the shipped order, 2), or per joint `knee=off,ankle_roll=10` (default: the
    /// shipped `config/ankle_knee.toml`, 30 Hz order 2 on both joints).
    #[arg(long)]
    pub lpf: Option<String>,
    /// The controller's M: `link` (the paper's, URDF link inertia only) or `link-rotor` (plus the
    /// reflected rotor inertia r²·J_m of the preset — a diagnostic: the loop then gets the K_p asked
    /// for and 25× more damping on the ankle roll).
    #[arg(long, value_enum, default_value_t = ControllerInertia::Link)]
    #[serde(serialize_with = "super::stage::as_value_enum")]
    pub controller_inertia: ControllerInertia,
    /// Lockstep trials run at once, each with its own frictiond, plant and IPC namespace (the
    /// results do not change, only the wall time). Default: the CPUs available. Real-time trials
    /// always run one at a time.
    #[arg(long)]
    pub jobs: Option<usize>,
}

/// What the computed-torque controller's M contains.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerInertia {
    /// URDF link inertia I_L (the paper's).
    Link,
    /// I_L + r²·J_m.
    LinkRotor,
}

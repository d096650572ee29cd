//! One closed-loop trial over shared memory: the experiment controller's loop.
//!
//! The plant is a [`Rig`] ([`super::rig`]): the two single-joint presets (each planned joint controlled by
//! [`ComputedTorque`] on its own link model) or the coupled leg (all six joints controlled at once by
//! [`LegComputedTorque`]); both run through the one loop of [`run_trial_on`].
//!
//! What this module **is**: [`TrialSpec`] (which
//! joints, gains, references, disturbance pulses and friction models) and [`run_trial`], which starts a
//! [`Session`] (frictiond + plant), then per received `JointStates` (seq k) computes τ_des for every
//! planned joint, publishes the `SimDisturbance` when it changes and the `TorqueRequest` with
//! `state_seq = k` (the lockstep protocol of the preamble), and records a [`TrialTrace`]: set-point,
//! measured and true position, τ_des, τ̂_F (from `DaemonStatus`, published every tick), true friction
//! and applied current (from `SimTruth`).
//!
//! What it is **not**: no metrics or tables (see [`super::metrics`], [`super::report`]).

use std::time::{Duration, Instant};

use frictionless_shm_types::sim::{SimDisturbance, SimTruth};
use frictionless_shm_types::{
    Channel, DaemonStatus, Inbox, Ipc, JointStates, MotorCurrentCommand, Outbox, TorqueRequest,
    monotonic_ns,
};

use super::ExperimentError;
use super::controller::{ComputedTorque, LegComputedTorque, Reference, Setpoint};
use super::oracle::OracleCompensation;
use super::rig::{JointSetup, Rig};
use super::session::{
    Binaries, DaemonJoint, FrictionModel, LawSettings, Lpf, Mode, PlantSpec, Session, interrupted,
};
use frictionless_sim::link::LinkDynamics;

/// An external torque pulse on the joint output (through `SimDisturbance`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pulse {
    /// Start time [s] after the trial start.
    pub start_s: f64,
    /// Duration [s].
    pub duration_s: f64,
    /// Torque [Nm] (positive increases s).
    pub torque_nm: f64,
}

impl Pulse {
    /// End time [s].
    pub fn end_s(&self) -> f64 {
        self.start_s + self.duration_s
    }
    fn at(&self, t_s: f64) -> f64 {
        if t_s >= self.start_s && t_s < self.end_s() {
            self.torque_nm
        } else {
            0.0
        }
    }
}

/// What one joint does in a trial.
#[derive(Clone, Debug)]
pub struct JointPlan {
    /// Payload index (0 = knee, 1 = ankle_roll).
    pub index: usize,
    /// K_p [1/s²] (K_d is the paper's 4/s).
    pub kp_per_s2: f64,
    /// Desired trajectory; the plant starts at its first point.
    pub reference: Reference,
    /// Optional disturbance.
    pub pulse: Option<Pulse>,
    /// Friction model frictiond runs for this joint.
    pub model: FrictionModel,
}

/// One trial.
#[derive(Clone, Debug)]
pub struct TrialSpec {
    /// Lockstep or real time.
    pub mode: Mode,
    /// Duration [s] of simulated time.
    pub duration_s: f64,
    /// The controlled joints (others are disabled and hang at their preset pose).
    pub joints: Vec<JointPlan>,
    /// Plant seed.
    pub seed: u64,
    /// Plant `--set` overrides (also applied to the controller's link model).
    pub sets: Vec<String>,
    /// PINN Δθ offset θ_off [motor rad] for frictiond per payload index (fixed across enables),
    /// `None` (or no entry) = latch at enable. The virtual plant's encoders read θ = r·φ, so 0 makes Δθ the
    /// absolute deflection — the offset of a training log latched once at its torque-free start.
    pub pinn_delta_theta_offset_motor_rad: Vec<Option<f64>>,
    /// frictiond with `kfc = 1`, no friction clip and no LPF, so the recorded τ̂_F is the model's
    /// raw output (for checking online against offline inference); `false` = the shipped law.
    pub raw_friction: bool,
    /// `kfc` per payload index instead of the shipped config's (`None` or no entry = shipped).
    pub kfc: Vec<Option<f64>>,
}

/// Further per-trial settings (kept out of [`TrialSpec`] so existing struct literals stay valid).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TrialOptions {
    /// τ̂_F low-pass per payload index instead of the shipped config's (`None` or no entry =
    /// shipped).
    pub lpf: Vec<Option<Lpf>>,
    /// Add the reflected rotor inertia r²·J_m (from the preset) to the controller's M (diagnostic;
    /// the paper's M is the link inertia only).
    pub rotor_inertia_in_m: bool,
}

/// Recorded signals of one joint, one entry per tick.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct JointTrace {
    /// Payload index.
    pub index: usize,
    /// Joint name.
    pub name: String,
    /// K_p used [1/s²].
    pub kp_per_s2: f64,
    /// Friction model label.
    pub model: String,
    /// kfc of the daemon config (τ̂_F includes it).
    pub kfc: f64,
    /// Time [s] (from the state seq).
    pub t_s: Vec<f64>,
    /// Set-point s_d [rad].
    pub s_des_rad: Vec<f64>,
    /// Measured s [rad] (what the controller used).
    pub s_rad: Vec<f64>,
    /// True s [rad] (SimTruth; NaN when the plant sent none).
    pub s_true_rad: Vec<f64>,
    /// Measured ṡ [rad/s] as the plant published it (the drive's causal estimate; what frictiond used).
    pub sdot_rad_s: Vec<f64>,
    /// True ṡ [rad/s] (SimTruth; NaN when the plant sent none).
    pub sdot_true_rad_s: Vec<f64>,
    /// Measured motor position θ [motor rad] as published (what frictiond used for Δθ).
    pub theta_motor_rad: Vec<f64>,
    /// Measured motor velocity ω_m [motor rad/s] as published.
    pub omega_motor_rad_s: Vec<f64>,
    /// τ_des [Nm].
    pub tau_des_nm: Vec<f64>,
    /// τ̂_F after clip, kfc and LPF [Nm] (DaemonStatus of the newest daemon tick; in lockstep exactly
    /// the daemon's output for the previous row's state, i.e. row k holds τ̂_F(state k − 1)). For the
    /// oracle: its compensation with the same one-row lag (row k holds the term added for state
    /// k − 1; the term for state k is inside row k's τ_des).
    pub tau_f_hat_nm: Vec<f64>,
    /// True friction τ_F [Nm] (SimTruth).
    pub tau_f_true_nm: Vec<f64>,
    /// Current the plant applied [A] (SimTruth).
    pub i_applied_a: Vec<f64>,
    /// External torque requested [Nm].
    pub tau_ext_nm: Vec<f64>,
    /// Daemon flags per tick (DaemonStatus::joint_flags).
    pub flags: Vec<u32>,
    /// Measured motor current [A] as published (robot convention: joint torque = r·k_t·i).
    pub i_meas_a: Vec<f64>,
    /// Winding temperature [°C] as published (NaN without a sensor).
    pub temperature_c: Vec<f64>,
    /// frictiond's current reference [A] (DaemonStatus::i_ref_a, with the same one-row lag as
    /// `tau_f_hat_nm`: row k holds the command computed for state k − 1; NaN before the first
    /// status).
    pub i_ref_a: Vec<f64>,
    /// True motor acceleration reflected to the joint φ̈ [rad/s²] (SimTruth; NaN when the plant
    /// sent none).
    pub phi_ddot_rad_s2: Vec<f64>,
}

/// Everything recorded in a trial.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct TrialTrace {
    /// One trace per planned joint, in plan order.
    pub joints: Vec<JointTrace>,
    /// Ticks run.
    pub ticks: u64,
    /// Wall-clock seconds of the control loop (without process start-up).
    pub loop_wall_s: f64,
    /// Wall-clock seconds including start-up and tear-down.
    pub total_wall_s: f64,
}

/// Waits for a value with `accept` true, up to `timeout`.
fn wait_for<T: std::fmt::Debug + Copy + iceoryx2::prelude::ZeroCopySend + 'static>(
    inbox: &Inbox<T>,
    timeout: Duration,
    accept: impl Fn(&T) -> bool,
) -> Result<Option<T>, ExperimentError> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = inbox.latest()?
            && accept(&v)
        {
            return Ok(Some(v));
        }
        let now = Instant::now();
        if now >= deadline || interrupted() {
            return Ok(None);
        }
        inbox.wait((deadline - now).min(Duration::from_millis(20)))?;
    }
}

/// Runs one trial through real processes (see the module doc) with default [`TrialOptions`].
pub fn run_trial(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    spec: &TrialSpec,
) -> Result<TrialTrace, ExperimentError> {
    run_trial_with(bins, setups, spec, &TrialOptions::default())
}

/// Runs one trial against the single-joint presets through real processes (see the module doc).
pub fn run_trial_with(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    spec: &TrialSpec,
    opts: &TrialOptions,
) -> Result<TrialTrace, ExperimentError> {
    run_trial_on(bins, &Rig::Pair(setups), spec, opts)
}

/// Runs one trial against `rig` through real processes (see the module doc). `spec` and `opts`
/// per-joint arrays (`kfc`, `lpf`, PINN offset) apply to payload indices 0 and 1 only; the leg's
/// other joints use the defaults.
pub fn run_trial_on(
    bins: &Binaries,
    rig: &Rig,
    spec: &TrialSpec,
    opts: &TrialOptions,
) -> Result<TrialTrace, ExperimentError> {
    let started = Instant::now();
    check_spec(rig, spec)?;
    let n = rig.dof();
    let mut session = new_session()?;
    // Declared after the session: the ports and the node drop first, then the session (children,
    // run directory).
    let ports = Ports::open(&session)?;
    start_children(bins, rig, spec, opts, &mut session, &ports)?;

    let mut ctrl = Control::new(rig, spec, opts)?;
    let laws = trial_laws(rig, spec, opts)?;
    let mut traces = empty_traces(rig, spec, &laws);
    let mut oracles = Oracles::new(spec, &laws)?;
    let enable_mask = spec.joints.iter().fold(0u64, |m, p| m | (1u64 << p.index));

    let loop_start = Instant::now();
    let mut seq0: Option<u64> = None;
    let mut last_seq = 0u64;
    let mut truth_ok = true;
    let mut status: Option<DaemonStatus> = None;
    let mut last_ext = vec![0.0f64; n];
    let mut ext = vec![0.0f64; n];
    let mut sps = vec![Setpoint::default(); spec.joints.len()];
    let mut taus = vec![0.0f64; spec.joints.len()];
    let mut req_seq = 0u64;
    let mut dist_seq = 0u64;
    let mut ticks = 0u64;
    loop {
        if interrupted() {
            return Err(ExperimentError::Interrupted);
        }
        let js = next_state(&ports.js_in, &mut session, last_seq, seq0.is_none())?;
        let s0 = *seq0.get_or_insert(js.seq);
        last_seq = js.seq;
        let t = (js.seq - s0) as f64 * 1e-3;
        if t >= spec.duration_s {
            break;
        }
        let truth = if truth_ok {
            next_truth(&ports.truth_in, js.seq, &mut truth_ok)?
        } else {
            None
        };
        let lockstep_after_first = spec.mode == Mode::Lockstep && ticks > 0;
        if let Some(st) = next_status(&ports.status_in, status, lockstep_after_first)? {
            status = Some(st);
        }
        let mut req = TorqueRequest::zeroed();
        ext.fill(0.0);
        for (sp, p) in sps.iter_mut().zip(&spec.joints) {
            *sp = p.reference.at(t);
        }
        ctrl.tau_des_nm(&js, &spec.joints, &sps, &mut taus)?;
        for (k, p) in spec.joints.iter().enumerate() {
            let j = p.index;
            let (tau, f_hat) = oracles.apply(k, j, &js, truth.as_ref(), taus[k], status)?;
            req.tau_des_nm[j] = tau;
            ext[j] = p.pulse.map_or(0.0, |pl| pl.at(t));
            traces[k].push_row(&Row {
                t_s: t,
                s_des_rad: sps[k].s_rad,
                state: &js,
                truth: truth.as_ref(),
                status: status.as_ref(),
                tau_des_nm: tau,
                tau_f_hat_nm: f_hat,
                tau_ext_nm: ext[j],
            });
        }
        if ext != last_ext {
            dist_seq += 1;
            publish_disturbance(&ports.dist_out, dist_seq, &ext)?;
            last_ext.copy_from_slice(&ext);
        }
        req_seq += 1;
        req.seq = req_seq;
        req.state_seq = js.seq;
        req.enable_mask = enable_mask;
        req.n_joints = n as u32;
        publish_request(&ports.req_out, &mut req)?;
        ticks += 1;
    }
    let loop_wall_s = loop_start.elapsed().as_secs_f64();
    session
        .check_alive()
        .map_err(|e| ExperimentError::AfterRun(Box::new(e)))?;
    Ok(TrialTrace {
        joints: traces,
        ticks,
        loop_wall_s,
        total_wall_s: started.elapsed().as_secs_f64(),
    })
}

/// A new session; its run directory is kept when `FRICTL_KEEP_RUN_DIR` is set.
fn new_session() -> Result<Session, ExperimentError> {
    let mut session = Session::new()?;
    if std::env::var_os("FRICTL_KEEP_RUN_DIR").is_some() {
        session.keep_dir(true);
        eprintln!("run directory kept: {}", session.dir.display());
    }
    Ok(session)
}

/// Starts frictiond (waiting until it subscribes to the requests) and the plant, at the trial's
/// initial pose.
fn start_children(
    bins: &Binaries,
    rig: &Rig,
    spec: &TrialSpec,
    opts: &TrialOptions,
    session: &mut Session,
    ports: &Ports,
) -> Result<(), ExperimentError> {
    let (daemon_joints, initial) = daemon_joints(rig, spec, opts);
    session.start_daemon(bins, spec.mode, &daemon_joints, spec.raw_friction, || {
        ports.req_ch.subscriber_count()
    })?;
    session.start_plant(
        bins,
        spec.mode,
        &PlantSpec {
            seed: spec.seed,
            preset: rig.preset_arg(),
            initial_pose_rad: initial,
            sets: spec.sets.clone(),
        },
    )?;
    Ok(())
}

/// The law settings of each planned joint: the shipped ones with the spec's kfc and the options'
/// filter where they set them.
fn trial_laws(
    rig: &Rig,
    spec: &TrialSpec,
    opts: &TrialOptions,
) -> Result<Vec<LawSettings>, ExperimentError> {
    spec.joints
        .iter()
        .map(|p| {
            LawSettings::shipped(
                &rig.params(p.index).joint,
                spec.kfc.get(p.index).copied().flatten(),
                opts.lpf.get(p.index).copied().flatten(),
            )
        })
        .collect()
}

/// Stamps `req` now and publishes it.
fn publish_request(
    out: &Outbox<TorqueRequest>,
    req: &mut TorqueRequest,
) -> Result<(), ExperimentError> {
    req.stamp_ns = monotonic_ns();
    out.publish(req).map_err(|source| ExperimentError::Publish {
        payload: "TorqueRequest",
        source,
    })
}

/// The controller's iceoryx2 ports in the session's services. Every service the daemon and the
/// plant use is created here, before either starts, so all agree on them from the start.
struct Ports {
    js_in: Inbox<JointStates>,
    truth_in: Inbox<SimTruth>,
    status_in: Inbox<DaemonStatus>,
    req_out: Outbox<TorqueRequest>,
    dist_out: Outbox<SimDisturbance>,
    /// The request service: the daemon's subscription to it says it is up.
    req_ch: Channel<TorqueRequest>,
    /// Created only so that the daemon and the plant agree on it.
    _cmd_ch: Channel<MotorCurrentCommand>,
    _node: Ipc,
}

impl Ports {
    fn open(session: &Session) -> Result<Self, ExperimentError> {
        let node = Ipc::open(&session.ipc, "experiment")?;
        let req_ch = node.torque_request()?;
        Ok(Self {
            js_in: node.joint_states()?.inbox()?,
            truth_in: node.sim_truth()?.inbox()?,
            status_in: node.daemon_status()?.inbox()?,
            req_out: req_ch.outbox()?,
            dist_out: node.sim_disturbance()?.outbox()?,
            req_ch,
            _cmd_ch: node.motor_current_command()?,
            _node: node,
        })
    }
}

/// The plant's `SimTruth` for state `seq` (waiting up to 500 ms); the first time none comes,
/// `truth_ok` is cleared with a warning and true friction is not recorded from then on.
fn next_truth(
    truth_in: &Inbox<SimTruth>,
    seq: u64,
    truth_ok: &mut bool,
) -> Result<Option<SimTruth>, ExperimentError> {
    let got = wait_for(truth_in, Duration::from_millis(500), |tr| tr.seq >= seq)?;
    if got.is_none() && interrupted() {
        return Err(ExperimentError::Interrupted);
    }
    if got.is_none() {
        *truth_ok = false;
        eprintln!("warning: the plant publishes no SimTruth; true friction is not recorded");
    }
    Ok(got)
}

/// The daemon's status to record with this state. In lockstep the daemon publishes one
/// `DaemonStatus` per tick, right after the command that answered the previous state; the plant can
/// publish the next state before that status is out. So after the first tick (`wait_fresh`) this
/// waits (briefly) for a status newer than `last`, so row k always holds the daemon's output for
/// state k − 1 (a fixed one-tick lag, no race); otherwise it takes the latest.
fn next_status(
    status_in: &Inbox<DaemonStatus>,
    last: Option<DaemonStatus>,
    wait_fresh: bool,
) -> Result<Option<DaemonStatus>, ExperimentError> {
    if wait_fresh {
        let fresh = |st: &DaemonStatus| last.is_none_or(|old| st.seq > old.seq);
        wait_for(status_in, Duration::from_millis(200), fresh)
    } else {
        Ok(status_in.latest()?)
    }
}

/// The oracle compensation of the planned joints that use it (`FrictionModel::Oracle`): the true
/// friction through the shipped law, added to τ_des by the controller instead of by frictiond.
struct Oracles {
    /// Per planned joint (`None`: frictiond compensates).
    laws: Vec<Option<OracleCompensation>>,
    /// The compensation each applied last tick (recorded as its τ̂_F, one tick behind as the
    /// daemon's).
    prev_nm: Vec<f64>,
}

impl Oracles {
    fn new(spec: &TrialSpec, laws: &[LawSettings]) -> Result<Self, ExperimentError> {
        let laws = spec
            .joints
            .iter()
            .zip(laws)
            .map(|(p, law)| {
                (p.model == FrictionModel::Oracle)
                    .then(|| OracleCompensation::new(*law))
                    .transpose()
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            prev_nm: vec![0.0; laws.len()],
            laws,
        })
    }

    /// Planned joint `k` (payload joint `j`): τ_des with the oracle's compensation added where it
    /// has one, and the τ̂_F to record (the daemon's, or the oracle's of the previous tick).
    fn apply(
        &mut self,
        k: usize,
        j: usize,
        js: &JointStates,
        truth: Option<&SimTruth>,
        tau_nm: f64,
        status: Option<DaemonStatus>,
    ) -> Result<(f64, f64), ExperimentError> {
        let daemon_f_hat = status.map_or(f64::NAN, |x| x.tau_f_hat_nm[j]);
        let Some(o) = &mut self.laws[k] else {
            return Ok((tau_nm, daemon_f_hat));
        };
        let tr = truth.ok_or(ExperimentError::OracleNoTruth)?;
        if tr.seq != js.seq {
            return Err(ExperimentError::OracleSeq {
                truth_seq: tr.seq,
                state_seq: js.seq,
            });
        }
        let comp = o.step(tr.tau_f_true_nm[j], js.sdot_rad_s[j]);
        let f_hat = std::mem::replace(&mut self.prev_nm[k], comp);
        Ok((tau_nm + comp, f_hat))
    }
}

/// Joint indices within the rig; the leg with every joint planned once; the oracle only in
/// lockstep with the shipped law.
fn check_spec(rig: &Rig, spec: &TrialSpec) -> Result<(), ExperimentError> {
    if let Rig::Leg(_) = rig {
        let mut seen = vec![false; rig.dof()];
        for p in &spec.joints {
            if let Some(s) = seen.get_mut(p.index) {
                *s = true;
            }
        }
        if spec.joints.len() != rig.dof() || seen.iter().any(|s| !s) {
            return Err(ExperimentError::LegPlan(rig.dof()));
        }
    }
    for p in &spec.joints {
        if p.index >= rig.dof() {
            return Err(ExperimentError::JointIndex(p.index));
        }
        if p.model == FrictionModel::Oracle && (spec.mode != Mode::Lockstep || spec.raw_friction) {
            return Err(ExperimentError::OracleMode);
        }
    }
    Ok(())
}

/// frictiond's joints (both presets; unplanned joints run no model) and the plant's initial pose
/// (a planned joint starts at its reference, the others at their preset pose).
fn daemon_joints(rig: &Rig, spec: &TrialSpec, opts: &TrialOptions) -> (Vec<DaemonJoint>, Vec<f64>) {
    let mut joints = vec![];
    let mut initial = vec![0.0; rig.dof()];
    for (i, init) in initial.iter_mut().enumerate() {
        let s = rig.params(i);
        let plan = spec.joints.iter().find(|p| p.index == i);
        *init = plan.map_or(s.initial_s_rad, |p| p.reference.start_rad());
        joints.push(DaemonJoint {
            name: s.joint.clone(),
            index: i,
            gear_ratio: s.gear_ratio_signed,
            kt_nm_per_a: s.kt_nm_per_a,
            model: plan.map_or(FrictionModel::None, |p| p.model.clone()),
            delta_theta_offset_motor_rad: spec
                .pinn_delta_theta_offset_motor_rad
                .get(i)
                .copied()
                .flatten(),
            kfc: spec.kfc.get(i).copied().flatten(),
            lpf: opts.lpf.get(i).copied().flatten(),
        });
    }
    (joints, initial)
}

/// The controller of a trial: the paper's computed torque per planned joint on its own link model,
/// or the whole-leg computed torque (with r²·J_m in M if asked, either way).
enum Control<'a> {
    /// One [`ComputedTorque`] per plan.
    Joints(Vec<ComputedTorque<&'a dyn LinkDynamics>>),
    /// The leg: buffers in payload order.
    Leg {
        ctrl: Box<LegComputedTorque>,
        s: Vec<f64>,
        sdot: Vec<f64>,
        sp: Vec<Setpoint>,
        tau: Vec<f64>,
    },
}

impl<'a> Control<'a> {
    fn new(rig: &Rig<'a>, spec: &TrialSpec, opts: &TrialOptions) -> Result<Self, ExperimentError> {
        let rotor = |i: usize| {
            if opts.rotor_inertia_in_m {
                rig.params(i).j_eq_kgm2()
            } else {
                0.0
            }
        };
        match *rig {
            Rig::Pair(setups) => Ok(Control::Joints(
                spec.joints
                    .iter()
                    .map(|p| ComputedTorque {
                        extra_inertia_kgm2: rotor(p.index),
                        ..ComputedTorque::paper(setups[p.index].link.as_ref(), p.kp_per_s2)
                    })
                    .collect(),
            )),
            Rig::Leg(leg) => {
                let n = leg.dof();
                let names: Vec<&str> = leg.params.joints.iter().map(|p| p.joint.as_str()).collect();
                let mut kp = vec![0.0; n];
                for p in &spec.joints {
                    kp[p.index] = p.kp_per_s2;
                }
                let mut ctrl = LegComputedTorque::new(leg.robot.clone(), &names, kp)?;
                for (i, x) in ctrl.extra_inertia_kgm2.iter_mut().enumerate() {
                    *x = rotor(i);
                }
                Ok(Control::Leg {
                    ctrl: Box::new(ctrl),
                    s: vec![0.0; n],
                    sdot: vec![0.0; n],
                    sp: vec![Setpoint::default(); n],
                    tau: vec![0.0; n],
                })
            }
        }
    }

    /// τ_des [Nm] per plan into `out` (plan order) for state `js` and set-points `sps` (plan order).
    fn tau_des_nm(
        &mut self,
        js: &JointStates,
        plans: &[JointPlan],
        sps: &[Setpoint],
        out: &mut [f64],
    ) -> Result<(), ExperimentError> {
        match self {
            Control::Joints(ctrls) => {
                for (k, p) in plans.iter().enumerate() {
                    let j = p.index;
                    out[k] = ctrls[k].tau_des_nm(js.s_rad[j], js.sdot_rad_s[j], &sps[k]);
                }
            }
            Control::Leg {
                ctrl,
                s,
                sdot,
                sp,
                tau,
            } => {
                let n = s.len();
                s.copy_from_slice(&js.s_rad[..n]);
                sdot.copy_from_slice(&js.sdot_rad_s[..n]);
                for (k, p) in plans.iter().enumerate() {
                    sp[p.index] = sps[k];
                }
                ctrl.tau_des_nm(s, sdot, sp, tau)?;
                for (k, p) in plans.iter().enumerate() {
                    out[k] = tau[p.index];
                }
            }
        }
        Ok(())
    }
}

/// One empty trace per planned joint, with the kfc its τ̂_F includes (0 without a model).
fn empty_traces(rig: &Rig, spec: &TrialSpec, laws: &[LawSettings]) -> Vec<JointTrace> {
    spec.joints
        .iter()
        .enumerate()
        .map(|(k, p)| JointTrace {
            index: p.index,
            name: rig.params(p.index).joint.clone(),
            kp_per_s2: p.kp_per_s2,
            model: p.model.label().to_owned(),
            kfc: if p.model == FrictionModel::None {
                0.0
            } else if spec.raw_friction {
                1.0
            } else {
                laws[k].kfc
            },
            ..JointTrace::default()
        })
        .collect()
}

/// The next `JointStates` (the first one, or one newer than `last_seq`); an error naming the plant's
/// and frictiond's last log lines after 10 s without one.
fn next_state(
    js_in: &Inbox<JointStates>,
    session: &mut Session,
    last_seq: u64,
    first: bool,
) -> Result<JointStates, ExperimentError> {
    match wait_for(js_in, Duration::from_secs(10), |s| {
        s.seq > last_seq || first
    })? {
        Some(js) => Ok(js),
        None => {
            if interrupted() {
                return Err(ExperimentError::Interrupted);
            }
            session.check_alive()?;
            Err(ExperimentError::NoStates {
                last_seq,
                plant_log: session.log_tail("plant"),
                frictiond_log: session.log_tail("frictiond"),
            })
        }
    }
}

/// Publishes the external torques `ext_nm` (one per joint) as `SimDisturbance` number `seq`.
fn publish_disturbance(
    out: &Outbox<SimDisturbance>,
    seq: u64,
    ext_nm: &[f64],
) -> Result<(), ExperimentError> {
    let mut d = SimDisturbance::zeroed();
    d.seq = seq;
    d.stamp_ns = monotonic_ns();
    d.n_joints = ext_nm.len() as u32;
    d.tau_ext_nm[..ext_nm.len()].copy_from_slice(ext_nm);
    out.publish(&d).map_err(|source| ExperimentError::Publish {
        payload: "SimDisturbance",
        source,
    })
}

/// What one tick records for one joint.
struct Row<'a> {
    t_s: f64,
    s_des_rad: f64,
    state: &'a JointStates,
    truth: Option<&'a SimTruth>,
    status: Option<&'a DaemonStatus>,
    tau_des_nm: f64,
    tau_f_hat_nm: f64,
    tau_ext_nm: f64,
}

impl JointTrace {
    /// Appends one tick (NaN where the plant sent no truth, flags 0 before the first status).
    fn push_row(&mut self, r: &Row) {
        let j = self.index;
        let (js, truth) = (r.state, r.truth);
        self.t_s.push(r.t_s);
        self.s_des_rad.push(r.s_des_rad);
        self.s_rad.push(js.s_rad[j]);
        self.sdot_rad_s.push(js.sdot_rad_s[j]);
        self.theta_motor_rad.push(js.theta_motor_rad[j]);
        self.omega_motor_rad_s.push(js.omega_motor_rad_s[j]);
        self.sdot_true_rad_s
            .push(truth.map_or(f64::NAN, |x| x.sdot_true_rad_s[j]));
        self.tau_des_nm.push(r.tau_des_nm);
        self.tau_ext_nm.push(r.tau_ext_nm);
        self.s_true_rad
            .push(truth.map_or(f64::NAN, |x| x.s_true_rad[j]));
        self.tau_f_true_nm
            .push(truth.map_or(f64::NAN, |x| x.tau_f_true_nm[j]));
        self.i_applied_a
            .push(truth.map_or(f64::NAN, |x| x.i_applied_a[j]));
        self.tau_f_hat_nm.push(r.tau_f_hat_nm);
        self.flags.push(r.status.map_or(0, |x| x.joint_flags[j]));
        self.i_meas_a.push(js.current_a[j]);
        self.temperature_c.push(js.temperature_c[j]);
        self.i_ref_a
            .push(r.status.map_or(f64::NAN, |x| x.i_ref_a[j]));
        self.phi_ddot_rad_s2
            .push(truth.map_or(f64::NAN, |x| x.phi_ddot_rad_s2[j]));
    }
}

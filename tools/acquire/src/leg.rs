//! Simultaneous excitation of the coupled leg: every joint plays its own protocol at once.
//!
//! What it is: [`leg_protocols`] (one [`ProtocolConfig`] per leg joint, scaled to that joint from
//! the knee preset's protocol: its own range, safety current and current amplitudes) and
//! [`run_leg_offline`], which plays them on a fresh [`LegPlant`]: one [`JointRunner`] per joint
//! (its own schedule, re-centring, position latch and current guard), all stepped together each
//! 1 kHz sample with every joint's current. The controllers know the nominal URDF: each joint's
//! gravity feed-forward is g_k(q) of the whole leg at the *measured* positions of every joint
//! ([`LegJointLink`]), its inertia M_kk at the start pose.
//!
//! What it is not: file output (the caller's sink gets every joint's row of a sample together) or
//! a live plant.

use std::sync::{Arc, Mutex, PoisonError};

use frictionless_dynamics::{Robot, Workspace};
use frictionless_sim::link::LinkDynamics;
use frictionless_sim::params::{ParamError, load_table};
use frictionless_sim::{LegError, LegParams, LegPlant, Measurement, PlantParams, Truth};

use std::collections::BTreeMap;

use frictionless_dataset::Dataset;
use frictionless_ident::preprocess::{
    JointStates, LabelFilter, PreprocessConfig, PreprocessError, PreprocessSummary, Ripple,
    WholeBody, preprocess_whole_body,
};

use crate::config::ProtocolConfig;
use crate::protocol::{AcquireError, ControllerModel, JointRunner, LogRow, RunSummary, schedule};

/// Why a leg acquisition failed.
#[derive(Debug, thiserror::Error)]
pub enum LegAcquireError {
    /// The protocol template or a `--set` on it is not acceptable.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The leg could not be built or stepped.
    #[error(transparent)]
    Leg(#[from] LegError),
    /// The run failed (in practice: the sink).
    #[error(transparent)]
    Run(#[from] AcquireError),
}

/// Factor on the smoother's acceleration process noise of the authors' separate-filter label
/// ([`separate_label_config`]) for a leg joint (1 = the knee's
/// [`frictionless_ident::kalman::KalmanConfig::knee`]).
///
/// The hip yaw's drive (small reflected rotor inertia, CSD-20) rings in its torsional mode when
/// the other joints whip the yaw axis; with the knee's smoother the label's s̈ and φ̂̈ miss that
/// motion and the friction label misses the friction's sign changes. A 100× process noise lets the
/// smoother follow it. The ankles are the end of the chain: their floor is the smoother's lag, which
/// a 1000× process noise lowers. The hips' pitch and roll and the knee keep the knee's smoother.
pub fn separate_kalman_q_acc_factor(joint: &str) -> f64 {
    if joint.contains("hip_yaw") {
        100.0
    } else if joint.contains("ankle") {
        1000.0
    } else {
        1.0
    }
}

/// The authors' separate-filter label of a leg joint's rows, the comparison:
/// [`PreprocessConfig::for_joint`] (the current through the zero-phase Butterworth) with the
/// smoother of [`separate_kalman_q_acc_factor`] and the reflected rotor inertia J_eq·φ̂̈
/// subtracted (the leg's plant keeps the rotor on the motor side of the flexspline, so the
/// link-side τ_ID holds no armature).
pub fn separate_label_config(p: &PlantParams) -> PreprocessConfig {
    let mut cfg = PreprocessConfig::for_joint(&p.joint);
    cfg.kalman.q[2] *= separate_kalman_q_acc_factor(&p.joint);
    cfg.subtract_reflected_inertia_kgm2 = p.j_eq_kgm2();
    cfg
}

/// Factor on the smoother's acceleration process noise of the leg's label ([`label_config`]),
/// every joint alike (1 = the knee's [`frictionless_ident::kalman::KalmanConfig::knee`]). With the
/// matched label the smoother's bandwidth is the whole label's; ten times the knee's process
/// noise is the single setting that measured best over the leg's six drives and several
/// protocols (`docs/results.md`, "The whole leg end to end").
pub const LABEL_Q_ACC_FACTOR: f64 = 10.0;

/// The label of a leg joint's rows: [`LabelFilter::Matched`] (the current through the smoother
/// that gives q̈ and φ̈) with the smoother of [`LABEL_Q_ACC_FACTOR`], the wave generator's ripple
/// step ([`Ripple::WaveGenerator`]) and the reflected rotor inertia J_eq·φ̂̈ subtracted.
pub fn label_config(p: &PlantParams) -> PreprocessConfig {
    let mut cfg = PreprocessConfig::for_joint(&p.joint);
    cfg.kalman.q[2] *= LABEL_Q_ACC_FACTOR;
    cfg.subtract_reflected_inertia_kgm2 = p.j_eq_kgm2();
    cfg.label_filter = LabelFilter::Matched;
    cfg.ripple = Ripple::WaveGenerator;
    cfg
}

/// One leg joint's labels from a simultaneous acquisition (see [`label_leg`]).
#[derive(Clone, Debug)]
pub struct LegJointLabels {
    /// The joint.
    pub joint: String,
    /// Its dataset labelled from the whole leg's state (every joint's logged position).
    pub full_state: Dataset,
    /// Its dataset labelled from the single-joint view (the other joints held at their mean
    /// logged positions), the comparison.
    pub single_joint_view: Dataset,
    /// label − truth RMS of `full_state` on valid, active, sliding rows [Nm] (None without truth
    /// or sliding rows).
    pub error_full_state_nm: Option<f64>,
    /// The same for `single_joint_view` [Nm].
    pub error_single_joint_view_nm: Option<f64>,
    /// The same errors with the authors' separate filters ([`separate_label_config`]) instead:
    /// (whole state, single-joint view) [Nm].
    pub error_separate_nm: (Option<f64>, Option<f64>),
    /// The label pipeline's summary of `full_state` (chunks, Δθ offset).
    pub summary: PreprocessSummary,
}

/// label − truth RMS on valid, active rows sliding faster than 0.03 rad/s [Nm] (None without truth
/// or without such rows).
pub fn label_error_rms_nm(ds: &Dataset) -> Option<f64> {
    let truth = ds.tau_f_true_nm.as_ref()?;
    let (mut e2, mut n) = (0.0, 0usize);
    for (k, t) in truth.iter().enumerate() {
        if ds.valid[k] && ds.active[k] && ds.sdot_rad_s[k].abs() > 0.03 {
            e2 += (ds.tau_f_label_nm[k] - t).powi(2);
            n += 1;
        }
    }
    (n > 0).then(|| (e2 / n as f64).sqrt())
}

/// Labels every joint of one simultaneous leg acquisition twice, in one pass over the joints: from
/// the whole leg's state (every joint's logged position through `robot`, the URDF the label
/// believes) and from the single-joint view, each with [`label_config`]; and measures both views'
/// error with the authors' separate filters ([`separate_label_config`]) too. `rows[k]` are the logged rows of
/// `leg.joints[k]`, all of one length.
pub fn label_leg(
    leg: &LegParams,
    robot: &Robot,
    rows: &[Vec<LogRow>],
) -> Result<Vec<LegJointLabels>, PreprocessError> {
    let names: Vec<String> = leg.joints.iter().map(|p| p.joint.clone()).collect();
    let q: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| r.iter().map(|x| x.meas.s_rad).collect())
        .collect();
    let n = names.len();
    if rows.len() != n {
        return Err(PreprocessError::Sidecar {
            path: "leg log".into(),
            msg: format!("{} joints' rows for a leg of {n} joints", rows.len()),
        });
    }
    let whole = WholeBody::new(robot.clone(), BTreeMap::new())?;
    let state = JointStates {
        names: names.clone(),
        q: q.clone(),
        qdot: vec![None; n],
        qddot: vec![None; n],
        base_quat_xyzw: None,
        base_frame: None,
        wrenches: Vec::new(),
    };
    let mut out = Vec::with_capacity(n);
    for (k, p) in leg.joints.iter().enumerate() {
        let log = crate::raw_log(&rows[k], 1);
        let mut meta = crate::log_meta(p);
        meta.plant_link = None;
        let cfg = label_config(p);
        let (full_state, summary) = preprocess_whole_body(&log, &meta, &whole, &state, &cfg)?;
        let held: BTreeMap<String, f64> = names
            .iter()
            .zip(&q)
            .filter(|(name, _)| **name != p.joint)
            .map(|(name, v)| (name.clone(), v.iter().sum::<f64>() / v.len().max(1) as f64))
            .collect();
        let single = WholeBody::new(robot.clone(), held)?;
        let own = JointStates {
            names: vec![p.joint.clone()],
            q: vec![q[k].clone()],
            qdot: vec![None],
            qddot: vec![None],
            base_quat_xyzw: None,
            base_frame: None,
            wrenches: Vec::new(),
        };
        let (single_joint_view, _) = preprocess_whole_body(&log, &meta, &single, &own, &cfg)?;
        let m = separate_label_config(p);
        let error_separate_nm = (
            label_error_rms_nm(&preprocess_whole_body(&log, &meta, &whole, &state, &m)?.0),
            label_error_rms_nm(&preprocess_whole_body(&log, &meta, &single, &own, &m)?.0),
        );
        out.push(LegJointLabels {
            joint: p.joint.clone(),
            error_full_state_nm: label_error_rms_nm(&full_state),
            error_single_joint_view_nm: label_error_rms_nm(&single_joint_view),
            error_separate_nm,
            full_state,
            single_joint_view,
            summary,
        });
    }
    Ok(out)
}

/// Breakaway friction of a drive at 25 °C (motor side + LuGre static level) [Nm].
fn breakaway_nm(p: &PlantParams) -> f64 {
    p.f_s0_nm + p.f_cm_nm
}

/// `protocol.KEY=VALUE` of a short leg protocol (one start, one sine frequency, one ramp pair, two
/// steps; ≈ 27 simulated seconds): the tests' and `frictl demo --robot leg --quick`'s.
pub const SHORT_PROTOCOL: [&str; 7] = [
    "protocol.n_starts=1",
    "protocol.recentre_s=1.0",
    "protocol.current_scale=0.4",
    "protocol.sines.amplitude_to_a=0.7",
    "protocol.sines.frequencies_hz=[0.7]",
    "protocol.ramps.slopes_a_per_s=[0.39]",
    "protocol.steps.levels_a=[0.8, -0.8]",
];

/// The re-centring and hold gains of every leg joint, applied before the caller's `sets`:
/// K_p 200 1/s², K_d 28 1/s (ζ ≈ 1). With the knee preset's 400 and 40, the hip pitch, carrying
/// the whole leg, held at its upper limit margin in a limit cycle of its drive's torsional mode
/// (≈ 77 Hz, current saturating at ±i_max), where no label can follow the motor.
pub const LEG_HOLD_GAINS: [&str; 2] = [
    "protocol.position_kp_per_s2=200",
    "protocol.position_kd_per_s=28",
];

/// One protocol per leg joint (the leg's order), from the knee preset's `[protocol]` with
/// [`LEG_HOLD_GAINS`] and then `sets` (`protocol.KEY=VALUE`) applied, then per joint: the range is the joint's limits, the safety
/// current its `i_max_a`, and `current_scale` is the knee's times (breakaway_j / breakaway_knee) ·
/// (k_t·|r|)_knee / (k_t·|r|)_j, so each joint's sines, ramps and steps reach the same multiples of
/// its own breakaway friction. The closed-loop tracking sets are off (the single-joint inertia of
/// their controller is not the leg's).
pub fn leg_protocols(
    leg: &LegParams,
    sets: &[String],
) -> Result<Vec<ProtocolConfig>, LegAcquireError> {
    let sets: Vec<String> = LEG_HOLD_GAINS
        .iter()
        .map(|s| (*s).to_owned())
        .chain(sets.iter().cloned())
        .collect();
    let table = load_table("knee", None, &sets)?;
    let template = ProtocolConfig::from_table(&table)?;
    let knee = PlantParams::from_table(&table)?;
    let knee_torque_per_a = knee.kt_nm_per_a * knee.gear_ratio_signed.abs();
    let mut out = Vec::with_capacity(leg.joints.len());
    for p in &leg.joints {
        let mut c = template.clone();
        c.range_lo_rad = p.joint_lo_rad;
        c.range_hi_rad = p.joint_hi_rad;
        c.max_safety_current_a = p.i_max_a;
        c.current_scale = template.current_scale * breakaway_nm(p) / breakaway_nm(&knee)
            * knee_torque_per_a
            / (p.kt_nm_per_a * p.gear_ratio_signed.abs());
        for t in c.tracking.values_mut() {
            t.enabled = false;
        }
        c.validate()?;
        out.push(c);
    }
    Ok(out)
}

/// The nominal leg and the newest measured positions, shared by the joints' controllers.
struct Shared {
    robot: Robot,
    ws: Workspace,
    q: Vec<f64>,
    g: Vec<f64>,
}

/// One leg joint as the controller's [`LinkDynamics`]: gravity g_k(q) of the nominal leg at the
/// positions last given to [`LegLinks::set_positions`] with this joint at the asked angle; inertia
/// M_kk at the start pose.
pub struct LegJointLink {
    shared: Arc<Mutex<Shared>>,
    /// Robot index of the joint.
    j: usize,
    inertia_kgm2: f64,
}

impl LinkDynamics for LegJointLink {
    fn inertia_kgm2(&self, _s_rad: f64) -> f64 {
        self.inertia_kgm2
    }

    fn gravity_nm(&self, s_rad: f64) -> f64 {
        let mut guard = self.shared.lock().unwrap_or_else(PoisonError::into_inner);
        let sh = &mut *guard;
        sh.q[self.j] = s_rad;
        match sh.robot.gravity_torques(&mut sh.ws, &sh.q, &mut sh.g) {
            Ok(()) => sh.g[self.j],
            Err(_) => 0.0,
        }
    }
}

/// The controllers' links of every leg joint (see [`LegJointLink`]).
pub struct LegLinks {
    shared: Arc<Mutex<Shared>>,
    /// Robot index per leg joint (the leg's order).
    order: Vec<usize>,
    /// One link per leg joint (the leg's order).
    pub links: Vec<LegJointLink>,
}

impl LegLinks {
    /// Links of `robot` (the nominal leg) for `joints`, inertias at `q0_rad` (the leg's order).
    pub fn new(robot: &Robot, joints: &[&str], q0_rad: &[f64]) -> Result<Self, LegAcquireError> {
        let dyn_err = |source| LegError::Dynamics {
            urdf: robot.source.clone(),
            source,
        };
        let n = robot.dof();
        let mut order = Vec::with_capacity(joints.len());
        for name in joints {
            order.push(robot.joint_index(name).map_err(dyn_err)?);
        }
        let mut q = vec![0.0; n];
        for (&j, &v) in order.iter().zip(q0_rad) {
            q[j] = v;
        }
        let mut ws = Workspace::new(robot);
        let mut m = nalgebra::DMatrix::zeros(n, n);
        robot.mass_matrix(&mut ws, &q, &mut m).map_err(dyn_err)?;
        let shared = Arc::new(Mutex::new(Shared {
            robot: robot.clone(),
            ws,
            q,
            g: vec![0.0; n],
        }));
        let links = order
            .iter()
            .map(|&j| LegJointLink {
                shared: shared.clone(),
                j,
                inertia_kgm2: m[(j, j)],
            })
            .collect();
        Ok(Self {
            shared,
            order,
            links,
        })
    }

    /// The newest measured positions [rad] (the leg's order).
    pub fn set_positions(&self, s_rad: impl Iterator<Item = f64>) {
        let mut sh = self.shared.lock().unwrap_or_else(PoisonError::into_inner);
        for (&j, s) in self.order.iter().zip(s_rad) {
            sh.q[j] = s;
        }
    }
}

/// Every joint of a multi-joint plant for one control period: the seam between the simultaneous
/// protocol and a plant (the offline [`LegPlant`] here, a live plant over shared memory in `frictl`).
pub trait LegIo {
    /// The latest measurement of joint `k` (before any command: the initial one).
    fn measurement(&self, k: usize) -> Measurement;
    /// The truth behind joint `k`'s latest measurement, if the plant is simulated.
    fn truth(&self, k: usize) -> Option<Truth>;
    /// Applies every joint's current `i_ref_a[k]` (robot convention) for one control period.
    fn exchange(&mut self, i_ref_a: &[f64]) -> Result<(), AcquireError>;
}

/// The offline leg as a [`LegIo`] (no external torque).
struct SimLeg {
    plant: LegPlant,
    tau_ext_nm: Vec<f64>,
}

impl LegIo for SimLeg {
    fn measurement(&self, k: usize) -> Measurement {
        self.plant.samples()[k].meas
    }
    fn truth(&self, k: usize) -> Option<Truth> {
        Some(self.plant.samples()[k].truth)
    }
    fn exchange(&mut self, i_ref_a: &[f64]) -> Result<(), AcquireError> {
        let t = self.plant.time_s();
        self.plant
            .step(i_ref_a, &self.tau_ext_nm)
            .map(|_| ())
            .map_err(|e| AcquireError::Io {
                time_s: t,
                why: e.to_string(),
            })
    }
}

/// One joint's sample of a leg run: the log row and the controller's velocity estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegRow {
    /// The row (measurement, current reference, chunk, mode, truth).
    pub row: LogRow,
    /// The controller's filtered encoder-difference velocity [rad/s].
    pub sdot_rad_s: f64,
}

/// Plays every joint's protocol (`protocols`, the leg's order, e.g. from [`leg_protocols`]) at
/// once on a new [`LegPlant`] from `leg` and `seed`, until every joint has played its last block
/// (a joint done early holds its position, rows inactive). Each sample, `sink` gets one row per
/// joint (the leg's order, with the plant's truth). Returns each joint's summary.
pub fn run_leg_offline(
    leg: &LegParams,
    protocols: &[ProtocolConfig],
    seed: u64,
    sink: &mut dyn FnMut(&[LogRow]) -> Result<(), AcquireError>,
) -> Result<Vec<RunSummary>, LegAcquireError> {
    let mut rows = Vec::with_capacity(leg.joints.len());
    run_leg_offline_with_velocity(leg, protocols, seed, &mut |r| {
        rows.clear();
        rows.extend(r.iter().map(|x| x.row));
        sink(&rows)
    })
}

/// Every joint's rows of [`run_leg_offline`] (`rows[k]`: joint k of `leg`, one per sample) and
/// each joint's summary.
pub fn run_leg_offline_rows(
    leg: &LegParams,
    protocols: &[ProtocolConfig],
    seed: u64,
) -> Result<(Vec<Vec<LogRow>>, Vec<RunSummary>), LegAcquireError> {
    let mut rows: Vec<Vec<LogRow>> = vec![Vec::new(); leg.joints.len()];
    let summaries = run_leg_offline(leg, protocols, seed, &mut |r| {
        for (k, row) in r.iter().enumerate() {
            rows[k].push(*row);
        }
        Ok(())
    })?;
    Ok((rows, summaries))
}

/// [`run_leg_offline`] with each joint's velocity estimate in the rows.
pub fn run_leg_offline_with_velocity(
    leg: &LegParams,
    protocols: &[ProtocolConfig],
    seed: u64,
    sink: &mut dyn FnMut(&[LegRow]) -> Result<(), AcquireError>,
) -> Result<Vec<RunSummary>, LegAcquireError> {
    let n = leg.joints.len();
    if protocols.len() != n {
        return Err(LegError::Dimension {
            what: "protocols",
            expected: n,
            got: protocols.len(),
        }
        .into());
    }
    let plant = LegPlant::new(leg.clone(), seed)?;
    let mut io = SimLeg {
        plant,
        tau_ext_nm: vec![0.0; n],
    };
    run_leg(&mut io, leg, protocols, sink)
}

/// Plays every joint's protocol at once on `io` (joint k of `io` = joint k of `leg`, whose
/// nominal model the controllers use), until every joint has played its last block. Each sample,
/// `sink` gets one row per joint. Returns each joint's summary.
pub fn run_leg(
    io: &mut dyn LegIo,
    leg: &LegParams,
    protocols: &[ProtocolConfig],
    sink: &mut dyn FnMut(&[LegRow]) -> Result<(), AcquireError>,
) -> Result<Vec<RunSummary>, LegAcquireError> {
    let n = leg.joints.len();
    if protocols.len() != n {
        return Err(LegError::Dimension {
            what: "protocols",
            expected: n,
            got: protocols.len(),
        }
        .into());
    }
    let nominal = leg.nominal_robot()?;
    let names: Vec<&str> = leg.joints.iter().map(|p| p.joint.as_str()).collect();
    let q0: Vec<f64> = (0..n).map(|k| io.measurement(k).s_rad).collect();
    let links = LegLinks::new(&nominal, &names, &q0)?;
    let models: Vec<ControllerModel<'_>> = leg
        .joints
        .iter()
        .zip(&links.links)
        .map(|(p, l)| ControllerModel::nominal(p, l))
        .collect();
    let blocks: Vec<_> = protocols.iter().map(schedule).collect();
    let mut runners: Vec<JointRunner<'_, '_>> = models
        .iter()
        .zip(protocols)
        .zip(&blocks)
        .zip(&q0)
        .map(|(((m, c), b), &s0)| JointRunner::new(m, c, b, s0))
        .collect();
    let mut rows: Vec<LegRow> = Vec::with_capacity(n);
    let mut i_ref = vec![0.0; n];
    while runners.iter().any(|r| !r.finished()) {
        links.set_positions((0..n).map(|k| io.measurement(k).s_rad));
        rows.clear();
        for (k, r) in runners.iter_mut().enumerate() {
            let row = r.next(io.measurement(k), io.truth(k));
            i_ref[k] = row.i_ref_a;
            rows.push(LegRow {
                row,
                sdot_rad_s: r.velocity_rad_s(),
            });
        }
        sink(&rows)?;
        io.exchange(&i_ref)?;
    }
    Ok(runners.into_iter().map(JointRunner::into_summary).collect())
}

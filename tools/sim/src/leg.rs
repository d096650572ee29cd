//! The coupled virtual leg: one harmonic drive per joint, coupled through a URDF's rigid-body dynamics.
//!
//! What it is: [`LegPlant`], N joints of a fixed-base URDF (by default the ergoCub left leg: hip
//! pitch/roll/yaw, knee, ankle pitch/roll; every other joint locked, see [`Reduction`]). Each joint has
//! the drive side of [`crate::Plant`] with its own [`PlantParams`] (current-loop lag, J_eq = r²·J_m,
//! nonlinear flexspline, motor-side friction, output-side LuGre with Stribeck, ripple and load term,
//! thermal ODE, sensors); the link side is the whole leg:
//!
//! `M(q)·q̈ + h(q, q̇) = τ_t − τ_Fj + τ_ext` (one equation per joint, q̈ by the articulated-body
//! algorithm [`Robot::aba`]), `J_eq,k·φ̈_k = r_k·k_t,k·i_k − τ_t,k − τ_Fm,k` per joint.
//!
//! Integration is the single-joint plant's: semi-implicit Euler at `dt_physics_s` (every joint's
//! preset must agree on it and on `substeps_per_sample`), the exact exponential LuGre update, the
//! thermal coefficients evaluated once per sample, and the same arithmetic as the single-joint fast
//! path (a leg of one joint reproduces [`crate::Plant`] to rounding, see the tests). Each joint draws
//! its T₀ and its current noise from its own ChaCha8 stream (joint k of the parameters: seed + k·φ₆₄,
//! joint 0 the seed itself).
//!
//! Truth for label-error measurements ([`JointSample`]): per joint the true friction τ_F = τ_Fm + τ_Fj
//! and its parts, the flexspline torque τ_t and the link torque τ_link = τ_t − τ_Fj + τ_ext (exactly
//! M(q)·q̈ + h(q, q̇) of the plant's own links: what a whole-state inverse-dynamics label computes when its
//! URDF is right).
//!
//! The plant's links may differ from the URDF's ([`Perturbation`]): masses, centres of mass and
//! rotational inertias of the moving bodies, seeded, relative magnitude, so that a label computed
//! from the nominal URDF meets a wrong model as it does on a real robot.
//!
//! What it is not: a controller, a protocol, a plant server, or a floating-base robot.

use std::collections::BTreeMap;

use frictionless_dynamics::{DynamicsError, Reduction, Robot, SpatialInertia, Workspace};
use nalgebra::{DMatrix, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::params::{ParamError, PlantParams, apply_set, builtin_preset, merge_tables};
use crate::plant::{
    FrictionConsts, Measurement, PlantState, Sensors, ThermalCoeffs, Truth, rotate,
    spring_deflection_rad, spring_nm,
};
use crate::stribeck::StribeckTable;

/// The ergoCub URDF (`tests/fixtures/ergocub/ergoCubSN001.urdf`, BSD 3-Clause, see
/// `tests/fixtures/ergocub/README.md`), embedded: `urdf = "ergocub"` in a leg preset.
pub const ERGOCUB_URDF: &str = include_str!("../../../tests/fixtures/ergocub/ergoCubSN001.urdf");
/// Where [`ERGOCUB_URDF`] lives in the repository.
pub const ERGOCUB_URDF_PATH: &str = "tests/fixtures/ergocub/ergoCubSN001.urdf";
/// The built-in leg preset (`config/presets/leg.toml`).
pub const LEG_PRESET_TOML: &str = include_str!("../../../config/presets/leg.toml");
/// The six joints of the ergoCub left leg, root to foot.
pub const LEFT_LEG_JOINTS: [&str; 6] = [
    "l_hip_pitch",
    "l_hip_roll",
    "l_hip_yaw",
    "l_knee",
    "l_ankle_pitch",
    "l_ankle_roll",
];

/// Golden-ratio increment that separates the joints' random streams.
const SEED_STRIDE: u64 = 0x9E37_79B9_7F4A_7C15;

/// A seeded perturbation of the plant's links relative to the URDF (see [`LegPlant`]).
///
/// For every moving body (the link of a kept joint with everything welded or locked to it), with
/// u ~ U(−1, 1) drawn independently: mass m·(1 + ε·u), centre of mass c + ε·|c|·(u, u, u) (each
/// component its own draw), rotational inertia about the centre of mass I_c·(1 + ε·u) (a positive
/// scale keeps it physical), ε = `relative`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Perturbation {
    /// Relative magnitude ε, in [0, 0.5].
    pub relative: f64,
    /// Seed of the draws.
    pub seed: u64,
}

/// Everything that defines a leg: the URDF, the joints with their drive parameters, the locked joints.
#[derive(Clone, Debug, PartialEq)]
pub struct LegParams {
    /// URDF file, or `ergocub` for the embedded [`ERGOCUB_URDF`].
    pub urdf: String,
    /// One drive per movable joint, in the order of the leg's inputs and outputs; each
    /// [`PlantParams::joint`] names its URDF joint. The `link` table is not used.
    pub joints: Vec<PlantParams>,
    /// Positions of the locked joints [rad] by name (URDF joints neither kept nor listed: 0).
    pub locked_q_rad: BTreeMap<String, f64>,
    /// Optional perturbation of the plant's links relative to the URDF.
    pub perturbation: Option<Perturbation>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LegTable {
    urdf: String,
    joints: Vec<String>,
    #[serde(default)]
    locked_q_rad: BTreeMap<String, f64>,
    #[serde(default)]
    perturbation: Option<Perturbation>,
}

/// Errors building or running a leg.
#[derive(Debug, thiserror::Error)]
pub enum LegError {
    /// A joint's parameters, or the leg table, are invalid.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// The URDF, a joint name or the dynamics failed.
    #[error("leg URDF {urdf}: {source}")]
    Dynamics {
        /// The URDF.
        urdf: String,
        /// What failed.
        source: DynamicsError,
    },
    /// Input slices of the wrong length.
    #[error("{what}: expected {expected} values (one per leg joint), got {got}")]
    Dimension {
        /// Which argument.
        what: &'static str,
        /// Joints of the leg.
        expected: usize,
        /// Values given.
        got: usize,
    },
}

impl LegParams {
    /// The built-in leg (`config/presets/leg.toml`): the ergoCub left leg, six presets.
    pub fn preset() -> Result<Self, ParamError> {
        Self::from_toml_str(LEG_PRESET_TOML, "<preset leg>", &[])
    }

    /// Parses a leg table (`[leg]` and one `[joint.<name>]` per joint, see `config/presets/leg.toml`);
    /// `sets` are `JOINT:key=value` overrides of one joint's drive (`l_knee:plant.f_c0_nm=3`) or
    /// `key=value` of every joint's, applied after the preset and the joint's own table.
    pub fn from_toml_str(text: &str, origin: &str, sets: &[String]) -> Result<Self, ParamError> {
        let table: toml::Table = text.parse().map_err(|e| ParamError::Toml {
            path: origin.to_owned(),
            source: Box::new(e),
        })?;
        let leg: LegTable = table
            .get("leg")
            .ok_or(ParamError::MissingTable("leg"))?
            .clone()
            .try_into()
            .map_err(|e: toml::de::Error| ParamError::Deserialize {
                table: "leg",
                source: Box::new(e),
            })?;
        let joint_tables = table
            .get("joint")
            .and_then(|v| v.as_table())
            .ok_or(ParamError::MissingTable("joint"))?;
        let names: Vec<&str> = leg.joints.iter().map(String::as_str).collect();
        crate::params::check_set_joints(sets, &names)?;
        let mut joints = Vec::with_capacity(leg.joints.len());
        for name in &leg.joints {
            let mut jt = joint_tables
                .get(name)
                .and_then(|v| v.as_table())
                .cloned()
                .ok_or(ParamError::Link(format!(
                    "{origin}: [leg] joints names {name:?} but there is no [joint.{name}] table"
                )))?;
            let preset = match jt.remove("preset") {
                Some(toml::Value::String(p)) => p,
                other => {
                    return Err(ParamError::Link(format!(
                        "{origin}: [joint.{name}] needs preset = \"knee\" or \"ankle_roll\", got {other:?}"
                    )));
                }
            };
            let base = builtin_preset(&preset).ok_or(ParamError::UnknownPreset(preset.clone()))?;
            let mut merged: toml::Table = base.parse().map_err(|e| ParamError::Toml {
                path: format!("<preset {preset}>"),
                source: Box::new(e),
            })?;
            merge_tables(&mut merged, jt);
            for s in sets {
                match crate::params::split_set_joint(s) {
                    (Some(j), kv) if j == name => apply_set(&mut merged, kv)?,
                    (Some(_), _) => {}
                    (None, kv) => apply_set(&mut merged, kv)?,
                }
            }
            let p = PlantParams::from_table(&merged)?;
            if &p.joint != name {
                return Err(ParamError::Link(format!(
                    "{origin}: [joint.{name}] sets plant.joint = {:?} (must be the same name)",
                    p.joint
                )));
            }
            joints.push(p);
        }
        let out = Self {
            urdf: leg.urdf,
            joints,
            locked_q_rad: leg.locked_q_rad,
            perturbation: leg.perturbation,
        };
        out.validate()?;
        Ok(out)
    }

    /// Checks the joints (each valid, distinct, one integration rate) and the perturbation.
    pub fn validate(&self) -> Result<(), ParamError> {
        let Some(first) = self.joints.first() else {
            return Err(ParamError::Link("a leg needs at least one joint".into()));
        };
        for (k, p) in self.joints.iter().enumerate() {
            p.validate()?;
            if self.joints[..k].iter().any(|o| o.joint == p.joint) {
                return Err(ParamError::Link(format!(
                    "joint {:?} is listed twice",
                    p.joint
                )));
            }
            if p.dt_physics_s != first.dt_physics_s
                || p.substeps_per_sample != first.substeps_per_sample
            {
                return Err(ParamError::Link(format!(
                    "joint {:?} integrates at dt = {} s × {} substeps, joint {:?} at {} s × {}: \
                     the joints of a leg share one integrator",
                    p.joint,
                    p.dt_physics_s,
                    p.substeps_per_sample,
                    first.joint,
                    first.dt_physics_s,
                    first.substeps_per_sample
                )));
            }
        }
        for &q in self.locked_q_rad.values() {
            crate::params::check("leg.locked_q_rad", q, true, "must be finite")?;
        }
        if let Some(pert) = &self.perturbation {
            crate::params::check(
                "leg.perturbation.relative",
                pert.relative,
                (0.0..=0.5).contains(&pert.relative),
                "must be in [0, 0.5]",
            )?;
        }
        Ok(())
    }

    /// The URDF model of the leg as the label sees it (kept joints movable, the rest locked).
    pub fn nominal_robot(&self) -> Result<Robot, LegError> {
        let red = Reduction {
            keep: self.joints.iter().map(|p| p.joint.clone()).collect(),
            locked_q: self
                .locked_q_rad
                .iter()
                .map(|(k, v)| (k.clone(), *v))
                .collect(),
        };
        let err = |source| LegError::Dynamics {
            urdf: self.urdf.clone(),
            source,
        };
        if self.urdf == "ergocub" {
            Robot::from_urdf_str_reduced(ERGOCUB_URDF, ERGOCUB_URDF_PATH, Some(&red)).map_err(err)
        } else {
            Robot::from_urdf_file_reduced(&self.urdf, Some(&red)).map_err(err)
        }
    }
}

/// Applies `pert` to the moving bodies of `robot` (see [`Perturbation`]).
pub fn perturb_links(robot: &mut Robot, pert: &Perturbation) {
    let mut rng = ChaCha8Rng::seed_from_u64(pert.seed);
    let e = pert.relative;
    for j in &mut robot.joints {
        let i = j.inertia;
        let mut u = || rng.random_range(-1.0..1.0);
        let mass = i.mass_kg * (1.0 + e * u());
        let c = i.com_m();
        let cn = c.norm();
        let com = c + Vector3::new(u(), u(), u()) * (e * cn);
        let ic = i.inertia_at_com_kg_m2() * (1.0 + e * u());
        j.inertia = SpatialInertia::from_com(mass, com, ic);
    }
}

/// One joint's 1 kHz output: sensors, the drive's truth and the link torque.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointSample {
    /// Emulated sensors of the joint (robot conventions, as [`crate::Sample::meas`]).
    pub meas: Measurement,
    /// The drive's truth over the last physics step (as [`crate::Sample::truth`]; `gravity_nm` is
    /// g_k(q) of the plant's links with the whole leg's q, `s_ddot_rad_s2` the coupled q̈_k).
    pub truth: Truth,
    /// Link torque τ_link = τ_t − τ_Fj + τ_ext = (M(q)·q̈ + h(q, q̇))_k of the plant's links [Nm].
    pub tau_link_nm: f64,
}

/// Forces of one drive at the start of a physics step.
#[derive(Clone, Copy, Debug, Default)]
struct DriveForces {
    tau_t: f64,
    tau_fm: f64,
    tau_fj: f64,
    z_new: f64,
    g_ss: f64,
    phi_dd: f64,
}

/// One joint's drive side (the single-joint plant without its link).
struct Drive {
    p: PlantParams,
    st: PlantState,
    rng: ChaCha8Rng,
    sensors: Sensors,
    two_r: f64,
    j_eq: f64,
    current_gain: f64,
    stribeck: Option<StribeckTable>,
    // reciprocals and products of the step (as the single-joint fast path)
    fk: FrictionConsts,
    inv_j_eq: f64,
    dt_per_c_th: f64,
    inv_r_th: f64,
    drive_nm_per_a: f64,
    // per sample: thermal coefficients, current reference; per step: sin/cos of s and of the motor
    // ripple angle, the forces
    tc: ThermalCoeffs,
    i_ref: f64,
    sin_s: f64,
    cos_s: f64,
    sin_m: f64,
    cos_m: f64,
    f: DriveForces,
    truth: Truth,
    meas: Measurement,
}

impl Drive {
    fn new(p: PlantParams, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let t0 = if p.t0_max_c > p.t0_min_c {
            rng.random_range(p.t0_min_c..p.t0_max_c)
        } else {
            p.t0_min_c
        };
        let dt = p.dt_physics_s;
        let j_eq = p.j_eq_kgm2();
        let c_th = p.tau_th_s / p.r_th_k_per_w;
        Self {
            st: PlantState {
                temperature_c: t0,
                ..PlantState::default()
            },
            rng,
            sensors: Sensors::new(&p),
            two_r: 2.0 * p.gear_ratio_signed.abs(),
            j_eq,
            current_gain: 1.0 - (-dt / p.tau_current_s).exp(),
            stribeck: if p.stribeck_exponent == 1.0 {
                None
            } else {
                StribeckTable::new(p.stribeck_exponent)
            },
            fk: FrictionConsts::new(&p, dt),
            inv_j_eq: 1.0 / j_eq,
            dt_per_c_th: dt / c_th,
            inv_r_th: 1.0 / p.r_th_k_per_w,
            drive_nm_per_a: p.gear_ratio_signed * p.kt_nm_per_a,
            tc: ThermalCoeffs::at(&p, t0),
            i_ref: 0.0,
            sin_s: 0.0,
            cos_s: 1.0,
            sin_m: 0.0,
            cos_m: 1.0,
            f: DriveForces::default(),
            truth: Truth::default(),
            meas: Measurement {
                time_s: 0.0,
                s_rad: 0.0,
                theta_motor_rad: 0.0,
                omega_motor_rad_s: 0.0,
                i_meas_a: 0.0,
                temperature_c: f64::NAN,
            },
            p,
        }
    }

    /// Start of a sample: thermal coefficients, the held current reference, sin/cos of the angles.
    fn begin_sample(&mut self, i_ref_a: f64) {
        self.i_ref = if i_ref_a.is_nan() {
            0.0
        } else {
            i_ref_a.clamp(-self.p.i_max_a, self.p.i_max_a)
        };
        self.tc = ThermalCoeffs::at(&self.p, self.st.temperature_c);
        (self.sin_s, self.cos_s) = self.st.s_rad.sin_cos();
        (self.sin_m, self.cos_m) = if self.p.e1 != 0.0 {
            (self.two_r * self.st.phi_rad + self.p.p1_rad).sin_cos()
        } else {
            (0.0, 1.0)
        };
    }

    /// The drive's forces at the start of a physics step: the single-joint fast path's expressions.
    #[inline(always)]
    fn forces(&mut self, friction: bool) {
        let p = &self.p;
        let tc = &self.tc;
        let PlantState {
            s_rad: s,
            s_dot_rad_s: sd,
            phi_rad: phi,
            phi_dot_rad_s: phid,
            z_rad: z,
            i_a: i,
            ..
        } = self.st;
        let tau_t = spring_nm(p, phi - s) + p.d_t_nms_per_rad * (phid - sd);
        let (tau_fm, tau_fj, z_new, g_ss) = if friction {
            self.fk.forces(
                p,
                tc,
                self.stribeck.as_ref(),
                sd,
                phid,
                z,
                tau_t,
                self.sin_m,
                (self.sin_s, self.cos_s),
            )
        } else {
            (0.0, 0.0, z, 0.0)
        };
        let phi_dd = (self.drive_nm_per_a * i - tau_t - tau_fm) * self.inv_j_eq;
        self.f = DriveForces {
            tau_t,
            tau_fm,
            tau_fj,
            z_new,
            g_ss,
            phi_dd,
        };
    }

    /// Semi-implicit Euler with the joint's coupled acceleration `s_dd`; returns (s, ṡ) after it.
    #[inline(always)]
    fn advance(&mut self, s_dd: f64, last: bool) -> (f64, f64) {
        let p = &self.p;
        let dt = p.dt_physics_s;
        let f = self.f;
        let st = &mut self.st;
        let (s, sd, phi, phid, i) = (
            st.s_rad,
            st.s_dot_rad_s,
            st.phi_rad,
            st.phi_dot_rad_s,
            st.i_a,
        );
        let phid_new = phid + f.phi_dd * dt;
        let sd_new = s_dd.mul_add(dt, sd);
        let heat_w = p.r_w_ohm * i * i + (f.tau_fm * phid).abs() + (f.tau_fj * sd).abs()
            - (st.temperature_c - p.t_amb_c) * self.inv_r_th;
        st.phi_dot_rad_s = phid_new;
        st.s_dot_rad_s = sd_new;
        st.phi_rad = phi + phid_new * dt;
        st.s_rad = s + sd_new * dt;
        st.z_rad = f.z_new;
        st.temperature_c += heat_w * self.dt_per_c_th;
        st.i_a = i + (self.i_ref - i) * self.current_gain;
        st.time_s += dt;
        if last {
            self.truth = Truth {
                tau_f_nm: f.tau_fm + f.tau_fj,
                tau_fm_nm: f.tau_fm,
                tau_fj_nm: f.tau_fj,
                tau_t_nm: f.tau_t,
                z_rad: f.z_new,
                phi_ddot_rad_s2: f.phi_dd,
                s_ddot_rad_s2: s_dd,
                gravity_nm: 0.0,
                g_ss_nm: f.g_ss,
                state: *st,
            };
        } else {
            rotate(&mut self.sin_s, &mut self.cos_s, st.s_rad - s, st.s_rad);
            if p.e1 != 0.0 {
                rotate(
                    &mut self.sin_m,
                    &mut self.cos_m,
                    self.two_r * (st.phi_rad - phi),
                    self.two_r * st.phi_rad + p.p1_rad,
                );
            }
        }
        (st.s_rad, sd_new)
    }
}

/// The coupled virtual leg (see the module documentation).
pub struct LegPlant {
    params: LegParams,
    nominal: Robot,
    robot: Robot,
    ws: Workspace,
    /// Drives in the robot's joint order.
    drives: Vec<Drive>,
    /// `order[k]`: robot index of the parameters' joint k.
    order: Vec<usize>,
    q: Vec<f64>,
    qd: Vec<f64>,
    q_last: Vec<f64>,
    tau: Vec<f64>,
    tau_ext: Vec<f64>,
    qdd: Vec<f64>,
    /// (sin q, cos q) per joint, robot order, from the drives' rotated pairs.
    sin_cos: Vec<(f64, f64)>,
    armature: Vec<f64>,
    samples: u64,
    friction: bool,
    out: Vec<JointSample>,
}

impl LegPlant {
    /// A leg at rest at each joint's `initial_s_rad`, every drive pre-wound to hold gravity, with the
    /// joints' T₀ and noise streams drawn from `seed`.
    pub fn new(params: LegParams, seed: u64) -> Result<Self, LegError> {
        params.validate()?;
        let nominal = params.nominal_robot()?;
        let mut robot = nominal.clone();
        if let Some(pert) = &params.perturbation {
            perturb_links(&mut robot, pert);
        }
        let n = robot.dof();
        let mut order = Vec::with_capacity(n);
        for p in &params.joints {
            order.push(
                robot
                    .joint_index(&p.joint)
                    .map_err(|source| LegError::Dynamics {
                        urdf: params.urdf.clone(),
                        source,
                    })?,
            );
        }
        // drives in robot order; joint k of the parameters draws from seed + k·stride
        let mut slots: Vec<Option<Drive>> = (0..n).map(|_| None).collect();
        for (k, p) in params.joints.iter().enumerate() {
            let s = seed.wrapping_add((k as u64).wrapping_mul(SEED_STRIDE));
            if let Some(slot) = slots.get_mut(order[k]) {
                *slot = Some(Drive::new(p.clone(), s));
            }
        }
        let drives: Vec<Drive> = slots.into_iter().flatten().collect();
        if drives.len() != n || n != params.joints.len() {
            return Err(LegError::Param(ParamError::Link(format!(
                "{}: the reduced model has {n} movable joints for {} drives",
                params.urdf,
                params.joints.len()
            ))));
        }
        let armature = drives.iter().map(|d| d.j_eq).collect();
        let mut leg = Self {
            ws: Workspace::new(&robot),
            nominal,
            robot,
            drives,
            order,
            q: vec![0.0; n],
            qd: vec![0.0; n],
            q_last: vec![0.0; n],
            tau: vec![0.0; n],
            tau_ext: vec![0.0; n],
            qdd: vec![0.0; n],
            sin_cos: vec![(0.0, 1.0); n],
            armature,
            samples: 0,
            friction: true,
            out: Vec::with_capacity(n),
            params,
        };
        let q0: Vec<f64> = leg.params.joints.iter().map(|p| p.initial_s_rad).collect();
        leg.reset_at_rest(&q0)?;
        Ok(leg)
    }

    /// Puts the leg at rest at `q0_rad` (parameters' joint order): q̇ = φ̇ = 0, every flexspline wound
    /// to hold the leg's gravity torque, z = 0, currents at their holding values; keeps T and time.
    pub fn reset_at_rest(&mut self, q0_rad: &[f64]) -> Result<(), LegError> {
        self.check_len("q0_rad", q0_rad.len())?;
        for (k, &q) in q0_rad.iter().enumerate() {
            self.q[self.order[k]] = q;
        }
        let mut g = vec![0.0; self.q.len()];
        self.robot
            .gravity_torques(&mut self.ws, &self.q, &mut g)
            .map_err(|source| self.dyn_err(source))?;
        for (j, d) in self.drives.iter_mut().enumerate() {
            let delta = spring_deflection_rad(&d.p, g[j]);
            d.st.s_rad = self.q[j];
            d.st.s_dot_rad_s = 0.0;
            d.st.phi_rad = self.q[j] + delta;
            d.st.phi_dot_rad_s = 0.0;
            d.st.z_rad = 0.0;
            d.st.i_a = g[j] / d.drive_nm_per_a;
            d.sensors.reset(&d.p, &d.st);
            d.truth = Truth {
                gravity_nm: g[j],
                tau_t_nm: g[j],
                state: d.st,
                ..Truth::default()
            };
            let t = d.st.time_s;
            d.meas = d.sensors.measure(&d.p, &d.st, &mut d.rng, t);
            self.qd[j] = 0.0;
            self.tau[j] = g[j];
        }
        self.fill_out();
        Ok(())
    }

    fn dyn_err(&self, source: DynamicsError) -> LegError {
        LegError::Dynamics {
            urdf: self.params.urdf.clone(),
            source,
        }
    }

    fn check_len(&self, what: &'static str, got: usize) -> Result<(), LegError> {
        if got == self.drives.len() {
            Ok(())
        } else {
            Err(LegError::Dimension {
                what,
                expected: self.drives.len(),
                got,
            })
        }
    }

    /// Turns every joint's friction (motor side and LuGre) on or off (on by default); off leaves the
    /// two-inertia drives and the rigid-body coupling (tests of the integrator and the coupling).
    pub fn set_friction(&mut self, on: bool) {
        self.friction = on;
    }

    /// The leg's parameters.
    pub fn params(&self) -> &LegParams {
        &self.params
    }

    /// The plant's rigid-body model (the URDF's, perturbed if the parameters say so).
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// The URDF's model of the leg (what a label uses), unperturbed.
    pub fn nominal_robot(&self) -> &Robot {
        &self.nominal
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.drives.len()
    }

    /// Joint names in the parameters' order (the order of every slice in and out).
    pub fn joint_names(&self) -> impl Iterator<Item = &str> {
        self.params.joints.iter().map(|p| p.joint.as_str())
    }

    /// Continuous state of joint `k` (parameters' order).
    pub fn state(&self, k: usize) -> PlantState {
        self.drives[self.order[k]].st
    }

    /// Overwrites the continuous state of joint `k` (tests, scenario setup); the time is kept.
    pub fn set_state(&mut self, k: usize, st: PlantState) {
        let j = self.order[k];
        let d = &mut self.drives[j];
        d.st = PlantState {
            time_s: d.st.time_s,
            ..st
        };
        self.q[j] = st.s_rad;
        self.qd[j] = st.s_dot_rad_s;
    }

    /// The most recent 1 kHz output of every joint (parameters' order; the initial one before the
    /// first [`LegPlant::step`]).
    pub fn samples(&self) -> &[JointSample] {
        &self.out
    }

    /// Simulated time [s].
    pub fn time_s(&self) -> f64 {
        self.samples as f64 * self.params.joints[0].sample_period_s()
    }

    /// Advances one control sample (`substeps_per_sample` physics steps) holding every joint's current
    /// reference `i_ref_a` [A] (robot convention, each saturated at its ±i_max, NaN → 0) and external
    /// joint torques `tau_ext_nm` [Nm], both in the parameters' joint order. Allocation-free.
    pub fn step(
        &mut self,
        i_ref_a: &[f64],
        tau_ext_nm: &[f64],
    ) -> Result<&[JointSample], LegError> {
        self.check_len("i_ref_a", i_ref_a.len())?;
        self.check_len("tau_ext_nm", tau_ext_nm.len())?;
        for (k, (&i, &t)) in i_ref_a.iter().zip(tau_ext_nm).enumerate() {
            let j = self.order[k];
            self.drives[j].begin_sample(i);
            self.tau_ext[j] = t;
        }
        let n = self.drives[0].p.substeps_per_sample;
        for step in 0..n {
            let last = step + 1 == n;
            for (j, d) in self.drives.iter_mut().enumerate() {
                d.forces(self.friction);
                self.tau[j] = d.f.tau_t - d.f.tau_fj + self.tau_ext[j];
            }
            if last {
                self.q_last.copy_from_slice(&self.q);
            }
            for (sc, d) in self.sin_cos.iter_mut().zip(&self.drives) {
                *sc = (d.sin_s, d.cos_s);
            }
            if let Err(source) = self.robot.aba_with_armature_sin_cos(
                &mut self.ws,
                &self.q,
                &self.sin_cos,
                &self.qd,
                &self.tau,
                None,
                &mut self.qdd,
            ) {
                return Err(self.dyn_err(source));
            }
            for (j, d) in self.drives.iter_mut().enumerate() {
                (self.q[j], self.qd[j]) = d.advance(self.qdd[j], last);
            }
        }
        self.samples += 1;
        let time_s = self.time_s();
        // gravity of the truth at the start of the last step, as the single-joint plant reports it
        if let Err(source) = self
            .robot
            .gravity_torques(&mut self.ws, &self.q_last, &mut self.qdd)
        {
            return Err(self.dyn_err(source));
        }
        for (j, d) in self.drives.iter_mut().enumerate() {
            d.st.time_s = time_s;
            d.truth.state = d.st;
            d.truth.gravity_nm = self.qdd[j];
            d.meas = d.sensors.measure(&d.p, &d.st, &mut d.rng, time_s);
        }
        self.fill_out();
        Ok(&self.out)
    }

    fn fill_out(&mut self) {
        self.out.clear();
        for &j in &self.order {
            let d = &self.drives[j];
            self.out.push(JointSample {
                meas: d.meas,
                truth: d.truth,
                tau_link_nm: self.tau[j],
            });
        }
    }

    /// Reflected rotor inertias J_eq = r²·J_m in the robot's joint order (the armature of the
    /// rigid-transmission limit, see [`Robot::aba_with_armature`]).
    pub fn armature_robot_order(&self) -> &[f64] {
        &self.armature
    }

    /// Joint positions q [rad] in the robot's joint order (for [`LegPlant::robot`]'s algorithms).
    pub fn q_robot_order(&self) -> &[f64] {
        &self.q
    }

    /// Joint velocities q̇ [rad/s] in the robot's joint order.
    pub fn qd_robot_order(&self) -> &[f64] {
        &self.qd
    }

    /// Mechanical energy [J]: the links' kinetic ½·q̇ᵀM(q)q̇ and gravity potential (zero at the root
    /// origin), and per drive ½J_eq·φ̇², the flexspline's ½k1·Δ² + ¼k3·Δ⁴ and the bristles' ½σ0·z².
    /// Exact only with `lost_motion_rad` = 0. Allocates (a diagnostic, not for the step loop).
    pub fn energy_j(&mut self) -> Result<f64, LegError> {
        let n = self.dof();
        let mut m = DMatrix::zeros(n, n);
        self.robot
            .mass_matrix(&mut self.ws, &self.q, &mut m)
            .map_err(|source| self.dyn_err(source))?;
        let qd = nalgebra::DVector::from_column_slice(&self.qd);
        let kinetic = 0.5 * qd.dot(&(&m * &qd));
        let x = self
            .robot
            .body_placements(&self.q)
            .map_err(|source| self.dyn_err(source))?;
        let g = self.robot.gravity_world_m_s2();
        let mut potential = 0.0;
        for (b, xb) in x.iter().enumerate().skip(1) {
            let i = &self.robot.joints[b - 1].inertia;
            let com_world = xb.rot * i.com_m() + xb.pos;
            potential -= i.mass_kg * g.dot(&com_world);
        }
        let mut drives = 0.0;
        for d in &self.drives {
            let st = &d.st;
            let delta = st.phi_rad - st.s_rad;
            drives += 0.5 * d.j_eq * st.phi_dot_rad_s * st.phi_dot_rad_s
                + 0.5 * d.p.k1_nm_per_rad * delta * delta
                + 0.25 * d.p.k3_nm_per_rad3 * delta.powi(4)
                + 0.5 * d.p.sigma0_nm_per_rad * st.z_rad * st.z_rad;
        }
        Ok(kinetic + potential + drives)
    }
}

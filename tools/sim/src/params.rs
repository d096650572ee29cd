//! Parameters of the virtual joint and the preset/override machinery.
//!
//! What it is: [`PlantParams`] (every physical, sensor and integration parameter of the simulator, serde,
//! SI units named in each field), the built-in presets `knee` and `ankle_roll` (TOML files in
//! `config/presets/`, embedded with `include_str!` so they work from any directory), and the override
//! layering used by `frictl sim` and `frictl acquire`: preset → `--params FILE` (deep merge) →
//! `--set key=value` (dotted keys). Unknown keys are errors, so a typo never silently does nothing.
//!
//! What it is not: the equations (see [`crate::plant`]) or the excitation protocol (the `protocol`
//! table of the same preset file belongs to `frictionless-acquire`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The built-in knee preset (`config/presets/knee.toml`).
pub const KNEE_PRESET_TOML: &str = include_str!("../../../config/presets/knee.toml");
/// The built-in ankle-roll preset (`config/presets/ankle_roll.toml`).
pub const ANKLE_ROLL_PRESET_TOML: &str = include_str!("../../../config/presets/ankle_roll.toml");

/// Names of the built-in presets.
pub const PRESET_NAMES: &[&str] = &["knee", "ankle_roll"];

/// Errors while loading, overriding or validating parameters.
#[derive(Debug, thiserror::Error)]
pub enum ParamError {
    /// The preset is neither a built-in name nor a readable file.
    #[error("unknown preset {0:?}: expected one of {PRESET_NAMES:?} or a path to a TOML file")]
    UnknownPreset(String),
    /// A parameter file could not be read.
    #[error("cannot read parameter file {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A parameter file is not valid TOML.
    #[error("parameter file {path} is not valid TOML: {source}")]
    Toml {
        /// The file (or `<preset NAME>`).
        path: String,
        /// The parse error.
        source: Box<toml::de::Error>,
    },
    /// A `--set` argument is not `key=value`.
    #[error("--set {0:?}: expected key=value with a dotted key, e.g. plant.k1_nm_per_rad=2e4")]
    BadSet(String),
    /// A `--set JOINT:key=value` names a joint that is not one of the presets.
    #[error("--set {set:?}: no preset {joint:?} among {presets:?}")]
    UnknownSetJoint {
        /// The whole argument.
        set: String,
        /// The joint prefix.
        joint: String,
        /// The presets of this run.
        presets: Vec<String>,
    },
    /// A `--set` key walks through a value that is not a table.
    #[error("--set {key:?}: {prefix:?} is not a table")]
    NotATable {
        /// The full key.
        key: String,
        /// The part that is not a table.
        prefix: String,
    },
    /// A required table is missing.
    #[error("parameters have no [{0}] table")]
    MissingTable(&'static str),
    /// The table does not deserialise (unknown key, wrong type, missing key).
    #[error("invalid [{table}] parameters: {source}")]
    Deserialize {
        /// The table name.
        table: &'static str,
        /// The serde error, naming the key.
        source: Box<toml::de::Error>,
    },
    /// The link dynamics could not be built (URDF missing, joint unknown).
    #[error("invalid [plant.link]: {0}")]
    Link(String),
    /// A value is out of its valid range.
    #[error("invalid parameter {key} = {value}: {why}")]
    Invalid {
        /// The key.
        key: &'static str,
        /// The offending value.
        value: f64,
        /// Why it is invalid.
        why: &'static str,
    },
}

/// How the link (everything after the flexspline) is modelled.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LinkModel {
    /// Analytic pendulum: constant inertia, g(s) = A·sin(s + phase).
    Pendulum {
        /// Link inertia about the joint axis I_L [kg·m²].
        inertia_kgm2: f64,
        /// Gravity torque amplitude A [Nm].
        gravity_amplitude_nm: f64,
        /// Gravity phase [rad].
        gravity_phase_rad: f64,
    },
    /// Link dynamics of one joint of a URDF (fixed base, every other joint held still), through
    /// [`frictionless_dynamics::Robot::single_joint_view`].
    Urdf {
        /// URDF file, or `virtual_leg` for the project's embedded leg model.
        urdf: String,
        /// Joint name in the URDF.
        joint: String,
        /// Positions of the other joints [rad] by name (absent ones are 0).
        #[serde(default)]
        other_joints_rad: std::collections::BTreeMap<String, f64>,
        /// Magnitude of gravity along −z of the world [m/s²] (absent: standard gravity,
        /// [`frictionless_dynamics::GRAVITY_M_S2`]).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        gravity_m_s2: Option<f64>,
    },
}

/// Sensor emulation parameters (1 kHz outputs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorParams {
    /// Joint encoder counts per joint revolution (2¹⁸ on ergoCub).
    pub joint_encoder_counts_per_rev: u32,
    /// Motor encoder counts per motor revolution (3600 on ergoCub).
    pub motor_encoder_counts_per_rev: u32,
    /// Motor velocity = motor-encoder difference over this many samples divided by its duration.
    pub motor_velocity_window_samples: u32,
    /// The motor encoder's kind: `absolute` (θ = r·φ at every power-up, the default) or
    /// `incremental` (the counter starts at 0 at every power-up: θ = r·(φ − φ at power-up), so each
    /// boot of the plant — its start or reset at rest — reads its own zero, as on a robot).
    #[serde(default)]
    pub motor_encoder: MotorEncoderKind,
    /// Standard deviation of the current-measurement noise σ_i [A].
    pub current_noise_std_a: f64,
    /// Current measurement resolution [A] (1 mA).
    pub current_resolution_a: f64,
    /// Whether the joint has a temperature sensor (else `temperature_c` is NaN).
    pub temperature_sensor: bool,
    /// Temperature resolution [°C].
    pub temperature_resolution_c: f64,
}

/// Whether the motor encoder keeps its zero across power-ups ([`SensorParams::motor_encoder`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotorEncoderKind {
    /// The same zero at every power-up.
    #[default]
    Absolute,
    /// Counts from 0 at every power-up.
    Incremental,
}

/// Every parameter of the virtual harmonic-drive joint (reference §2–§5).
///
/// Equations use joint-side units and |r|; `gear_ratio_signed` is the robot's convention, applied to
/// sensors (θ = r_signed·φ) and commands (joint torque = r_signed·k_t·i).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantParams {
    /// Joint name (e.g. `l_knee`).
    pub joint: String,
    /// Signed gear ratio r (robot `Gearbox_M2J`, e.g. −100).
    pub gear_ratio_signed: f64,
    /// Torque constant k_t [Nm/A].
    pub kt_nm_per_a: f64,
    /// Current reference saturation ±i_max [A].
    pub i_max_a: f64,
    /// Current-loop time constant τ_i [s].
    pub tau_current_s: f64,
    /// Motor rotor + wave-generator inertia J_m [kg·m²] (motor side; J_eq = r²·J_m).
    pub j_motor_kgm2: f64,
    /// Initial joint angle s₀ [rad] (the drive starts pre-wound to hold gravity).
    pub initial_s_rad: f64,
    /// Flexspline linear stiffness k1 [Nm/rad].
    pub k1_nm_per_rad: f64,
    /// Flexspline cubic stiffness k3 [Nm/rad³].
    pub k3_nm_per_rad3: f64,
    /// Flexspline damping d_t [Nm·s/rad].
    pub d_t_nms_per_rad: f64,
    /// Half-width δ_b of the optional lost-motion dead-zone [rad] (0 = off).
    pub lost_motion_rad: f64,
    /// Corner smoothing of the dead-zone [rad].
    pub lost_motion_smoothing_rad: f64,
    /// Motor-side Coulomb friction F_cm [Nm, joint side].
    pub f_cm_nm: f64,
    /// Motor-side Coulomb smoothing velocity ε_m [rad/s].
    pub eps_m_rad_s: f64,
    /// Motor-side viscous friction σ_2m at 25 °C [Nm·s/rad].
    pub sigma2m_nms_per_rad: f64,
    /// Output-side Coulomb level F_c0 [Nm].
    pub f_c0_nm: f64,
    /// Direction-dependent Coulomb part ΔF_c [Nm] (+ΔF_c for ṡ > 0).
    pub delta_f_c_nm: f64,
    /// Output-side static friction F_s0 [Nm].
    pub f_s0_nm: f64,
    /// Stribeck velocity v_s [rad/s].
    pub v_s_rad_s: f64,
    /// Stribeck exponent δ.
    pub stribeck_exponent: f64,
    /// LuGre bristle stiffness σ0 [Nm/rad].
    pub sigma0_nm_per_rad: f64,
    /// LuGre bristle damping σ1 [Nm·s/rad] (scaled by exp(−(ṡ/v_s)²)).
    pub sigma1_nms_per_rad: f64,
    /// Output-side viscous friction σ_2j at 25 °C [Nm·s/rad].
    pub sigma2j_nms_per_rad: f64,
    /// Load-dependent Coulomb coefficient μ (adds μ·|τ_t| to g_ss).
    pub mu_load: f64,
    /// Friction ripple at 2/rev of the motor, relative amplitude e1.
    pub e1: f64,
    /// Friction ripple at 1/rev of the output, relative amplitude e2.
    pub e2: f64,
    /// Phase p1 of the motor ripple [rad].
    pub p1_rad: f64,
    /// Phase p2 of the output ripple [rad].
    pub p2_rad: f64,
    /// Viscous temperature coefficient β_v [1/K].
    pub beta_v_per_k: f64,
    /// Coulomb/static temperature coefficient β_c [1/K].
    pub beta_c_per_k: f64,
    /// Winding resistance R_w [Ω].
    pub r_w_ohm: f64,
    /// Thermal resistance to ambient R_th [K/W].
    pub r_th_k_per_w: f64,
    /// Thermal time constant τ_th = R_th·C_th [s].
    pub tau_th_s: f64,
    /// Ambient temperature [°C].
    pub t_amb_c: f64,
    /// Lower bound of the initial temperature draw T₀ ~ U(min, max) [°C].
    pub t0_min_c: f64,
    /// Upper bound of the initial temperature draw [°C] (equal to the minimum for a fixed T₀).
    pub t0_max_c: f64,
    /// Lower end of the joint range [rad].
    pub joint_lo_rad: f64,
    /// Upper end of the joint range [rad].
    pub joint_hi_rad: f64,
    /// Physics step [s] (5e-5 = 20 kHz).
    pub dt_physics_s: f64,
    /// Physics steps per 1 kHz sample.
    pub substeps_per_sample: u32,
    /// Link model.
    pub link: LinkModel,
    /// Sensor emulation.
    pub sensors: SensorParams,
    /// The joint torque sensor of a torque-sensed joint (`[plant.torque_sensor]`, optional; read only
    /// by `frictl acquire --sensor torque`, see [`crate::torque_sensor`]).
    #[serde(default)]
    pub torque_sensor: TorqueSensorParams,
}

impl PlantParams {
    /// Parses the `[plant]` table of a merged parameter table and validates it.
    pub fn from_table(table: &toml::Table) -> Result<Self, ParamError> {
        let plant = table
            .get("plant")
            .and_then(|v| v.as_table())
            .ok_or(ParamError::MissingTable("plant"))?;
        let p: PlantParams =
            plant
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| ParamError::Deserialize {
                    table: "plant",
                    source: Box::new(e),
                })?;
        p.validate()?;
        Ok(p)
    }

    /// Loads a built-in preset (or a preset file) with no overrides.
    pub fn preset(name: &str) -> Result<Self, ParamError> {
        Self::from_table(&load_table(name, None, &[])?)
    }

    /// |r|, the ratio used by the equations.
    pub fn ratio_abs(&self) -> f64 {
        self.gear_ratio_signed.abs()
    }

    /// Sign of the robot's gear ratio (±1).
    pub fn ratio_sign(&self) -> f64 {
        self.gear_ratio_signed.signum()
    }

    /// Reflected motor inertia J_eq = r²·J_m [kg·m², joint side].
    pub fn j_eq_kgm2(&self) -> f64 {
        self.gear_ratio_signed * self.gear_ratio_signed * self.j_motor_kgm2
    }

    /// Control period of the sampled outputs [s] (dt·substeps, 1 ms by default).
    pub fn sample_period_s(&self) -> f64 {
        self.dt_physics_s * f64::from(self.substeps_per_sample)
    }

    /// Checks every value is finite and in its physical range.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.torque_sensor.validate()?;
        check(
            "gear_ratio_signed",
            self.gear_ratio_signed,
            self.gear_ratio_signed.abs() >= 1e-6,
            "must be non-zero",
        )?;
        self.check_signs()?;
        self.check_relations()?;
        self.check_sensor_counts()?;
        self.check_link()
    }

    /// The values that must be positive, then those that must be non-negative.
    fn check_signs(&self) -> Result<(), ParamError> {
        let pos = "must be > 0";
        let nonneg = "must be >= 0";
        for (k, v) in [
            ("kt_nm_per_a", self.kt_nm_per_a),
            ("i_max_a", self.i_max_a),
            ("tau_current_s", self.tau_current_s),
            ("j_motor_kgm2", self.j_motor_kgm2),
            ("k1_nm_per_rad", self.k1_nm_per_rad),
            ("eps_m_rad_s", self.eps_m_rad_s),
            ("f_c0_nm", self.f_c0_nm),
            ("f_s0_nm", self.f_s0_nm),
            ("v_s_rad_s", self.v_s_rad_s),
            ("stribeck_exponent", self.stribeck_exponent),
            ("sigma0_nm_per_rad", self.sigma0_nm_per_rad),
            ("lost_motion_smoothing_rad", self.lost_motion_smoothing_rad),
            ("r_th_k_per_w", self.r_th_k_per_w),
            ("tau_th_s", self.tau_th_s),
            ("dt_physics_s", self.dt_physics_s),
        ] {
            check(k, v, v > 0.0, pos)?;
        }
        for (k, v) in [
            ("k3_nm_per_rad3", self.k3_nm_per_rad3),
            ("d_t_nms_per_rad", self.d_t_nms_per_rad),
            ("lost_motion_rad", self.lost_motion_rad),
            ("f_cm_nm", self.f_cm_nm),
            ("sigma2m_nms_per_rad", self.sigma2m_nms_per_rad),
            ("sigma1_nms_per_rad", self.sigma1_nms_per_rad),
            ("sigma2j_nms_per_rad", self.sigma2j_nms_per_rad),
            ("mu_load", self.mu_load),
            ("e1", self.e1),
            ("e2", self.e2),
            ("beta_v_per_k", self.beta_v_per_k),
            ("beta_c_per_k", self.beta_c_per_k),
            ("r_w_ohm", self.r_w_ohm),
            (
                "sensors.current_noise_std_a",
                self.sensors.current_noise_std_a,
            ),
            (
                "sensors.current_resolution_a",
                self.sensors.current_resolution_a,
            ),
            (
                "sensors.temperature_resolution_c",
                self.sensors.temperature_resolution_c,
            ),
        ] {
            check(k, v, v >= 0.0, nonneg)?;
        }
        Ok(())
    }

    /// The values bounded by others (friction levels, temperatures, joint range, substeps) and
    /// those that need only be finite.
    fn check_relations(&self) -> Result<(), ParamError> {
        check(
            "delta_f_c_nm",
            self.delta_f_c_nm,
            self.delta_f_c_nm.abs() < self.f_c0_nm,
            "|delta_f_c_nm| must be below f_c0_nm",
        )?;
        check(
            "e1",
            self.e1 + self.e2,
            self.e1 + self.e2 < 1.0,
            "e1 + e2 must be below 1 (friction level stays positive)",
        )?;
        for (k, v) in [
            ("p1_rad", self.p1_rad),
            ("p2_rad", self.p2_rad),
            ("initial_s_rad", self.initial_s_rad),
            ("t_amb_c", self.t_amb_c),
            ("t0_min_c", self.t0_min_c),
        ] {
            check(k, v, true, "must be finite")?;
        }
        check(
            "t0_max_c",
            self.t0_max_c,
            self.t0_max_c >= self.t0_min_c,
            "must be >= t0_min_c",
        )?;
        check(
            "joint_hi_rad",
            self.joint_hi_rad,
            self.joint_hi_rad > self.joint_lo_rad && self.joint_lo_rad.is_finite(),
            "must be above a finite joint_lo_rad",
        )?;
        check(
            "substeps_per_sample",
            f64::from(self.substeps_per_sample),
            self.substeps_per_sample >= 1,
            "must be >= 1",
        )?;
        Ok(())
    }

    /// The encoders' counts per revolution and the velocity window: at least 1.
    fn check_sensor_counts(&self) -> Result<(), ParamError> {
        let enc = &self.sensors;
        check(
            "sensors.joint_encoder_counts_per_rev",
            f64::from(enc.joint_encoder_counts_per_rev),
            enc.joint_encoder_counts_per_rev >= 1,
            "must be >= 1",
        )?;
        check(
            "sensors.motor_encoder_counts_per_rev",
            f64::from(enc.motor_encoder_counts_per_rev),
            enc.motor_encoder_counts_per_rev >= 1,
            "must be >= 1",
        )?;
        check(
            "sensors.motor_velocity_window_samples",
            f64::from(enc.motor_velocity_window_samples),
            enc.motor_velocity_window_samples >= 1,
            "must be >= 1",
        )?;
        Ok(())
    }

    /// The link model's values: finite, a pendulum's inertia positive.
    fn check_link(&self) -> Result<(), ParamError> {
        let pos = "must be > 0";
        match &self.link {
            LinkModel::Urdf {
                other_joints_rad, ..
            } => {
                for &q in other_joints_rad.values() {
                    check("link.other_joints_rad", q, true, "must be finite")?;
                }
            }
            &LinkModel::Pendulum {
                inertia_kgm2,
                gravity_amplitude_nm,
                gravity_phase_rad,
            } => {
                check("link.inertia_kgm2", inertia_kgm2, inertia_kgm2 > 0.0, pos)?;
                check(
                    "link.gravity_amplitude_nm",
                    gravity_amplitude_nm,
                    true,
                    "must be finite",
                )?;
                check(
                    "link.gravity_phase_rad",
                    gravity_phase_rad,
                    true,
                    "must be finite",
                )?;
            }
        }
        Ok(())
    }
}

/// The TOML text of a built-in preset, or `None` for an unknown name.
pub fn builtin_preset(name: &str) -> Option<&'static str> {
    match name {
        "knee" | "l_knee" => Some(KNEE_PRESET_TOML),
        "ankle_roll" | "l_ankle_roll" => Some(ANKLE_ROLL_PRESET_TOML),
        _ => None,
    }
}

fn parse_table(text: &str, origin: &str) -> Result<toml::Table, ParamError> {
    text.parse::<toml::Table>().map_err(|e| ParamError::Toml {
        path: origin.to_owned(),
        source: Box::new(e),
    })
}

fn read_table(path: &Path) -> Result<toml::Table, ParamError> {
    let text = frictionless::regular_file::read_text(path).map_err(|source| ParamError::Io {
        path: path.to_owned(),
        source,
    })?;
    parse_table(&text, &path.display().to_string())
}

/// Deep-merges `over` into `base`: tables merge key by key, every other value replaces.
pub fn merge_tables(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Splits a `--set` argument into its joint prefix (`ankle_roll:plant.t0_min_c=30` → `Some("ankle_roll")`)
/// and the `key=value` part; an argument without a prefix applies to every preset.
pub fn split_set_joint(set: &str) -> (Option<&str>, &str) {
    match set.split_once(':') {
        Some((joint, rest)) if !joint.contains('=') => (Some(joint.trim()), rest),
        _ => (None, set),
    }
}

/// Checks that every joint prefix in `sets` names one of `presets` (before anything is loaded, so a
/// misspelt joint is an error rather than an override silently applied to nothing).
pub fn check_set_joints(sets: &[String], presets: &[&str]) -> Result<(), ParamError> {
    for set in sets {
        if let (Some(joint), _) = split_set_joint(set)
            && !presets.contains(&joint)
        {
            return Err(ParamError::UnknownSetJoint {
                set: set.clone(),
                joint: joint.to_owned(),
                presets: presets.iter().map(|p| (*p).to_owned()).collect(),
            });
        }
    }
    Ok(())
}

/// Applies one `key=value` override with a dotted key. The value is parsed as a TOML value
/// (numbers, booleans, arrays, quoted strings); anything else is taken as a bare string.
pub fn apply_set(table: &mut toml::Table, set: &str) -> Result<(), ParamError> {
    let (key, value) = set
        .split_once('=')
        .ok_or_else(|| ParamError::BadSet(set.to_owned()))?;
    let key = key.trim();
    let value = value.trim();
    if key.is_empty() || key.split('.').any(str::is_empty) {
        return Err(ParamError::BadSet(set.to_owned()));
    }
    let parsed: toml::Value = value
        .parse::<toml::Value>()
        .unwrap_or_else(|_| toml::Value::String(value.to_owned()));
    let parts: Vec<&str> = key.split('.').collect();
    let mut cur = table;
    for (n, part) in parts[..parts.len() - 1].iter().enumerate() {
        let entry = cur
            .entry(part.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = entry.as_table_mut().ok_or_else(|| ParamError::NotATable {
            key: key.to_owned(),
            prefix: parts[..=n].join("."),
        })?;
    }
    cur.insert(parts[parts.len() - 1].to_owned(), parsed);
    Ok(())
}

/// Loads a preset (built-in name or TOML path), deep-merges the optional `params_file` over it, then
/// applies each `key=value` of `sets` in order (a `JOINT:key=value` only when `JOINT` is `preset`, see
/// [`check_set_joints`]). Returns the merged table (with `plant` and `protocol`).
pub fn load_table(
    preset: &str,
    params_file: Option<&Path>,
    sets: &[String],
) -> Result<toml::Table, ParamError> {
    let mut table = match builtin_preset(preset) {
        Some(text) => parse_table(text, &format!("<preset {preset}>"))?,
        None => {
            let path = Path::new(preset);
            if path.is_file() {
                read_table(path)?
            } else {
                return Err(ParamError::UnknownPreset(preset.to_owned()));
            }
        }
    };
    if let Some(file) = params_file {
        merge_tables(&mut table, read_table(file)?);
    }
    for s in sets {
        match split_set_joint(s) {
            (Some(joint), kv) if joint == preset => apply_set(&mut table, kv)?,
            (Some(_), _) => {}
            (None, kv) => apply_set(&mut table, kv)?,
        }
    }
    Ok(table)
}

/// Parameters of the joint torque sensor (`[plant.torque_sensor]`, every key optional).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TorqueSensorParams {
    /// White measurement noise σ [Nm] (default 0.02 Nm: a strain-gauge joint sensor of ≈ 50 Nm range).
    pub noise_std_nm: f64,
    /// Constant offset (zero drift) [Nm] (default 0.05 Nm).
    pub offset_nm: f64,
    /// Resolution [Nm] (default 1 mNm; 0 = unquantised).
    pub resolution_nm: f64,
}

impl Default for TorqueSensorParams {
    fn default() -> Self {
        Self {
            noise_std_nm: 0.02,
            offset_nm: 0.05,
            resolution_nm: 1e-3,
        }
    }
}

impl TorqueSensorParams {
    /// Checks every value is finite and the noise and resolution are ≥ 0.
    pub fn validate(&self) -> Result<(), ParamError> {
        check(
            "torque_sensor.noise_std_nm",
            self.noise_std_nm,
            self.noise_std_nm >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "torque_sensor.offset_nm",
            self.offset_nm,
            self.offset_nm.is_finite(),
            "must be finite",
        )?;
        check(
            "torque_sensor.resolution_nm",
            self.resolution_nm,
            self.resolution_nm >= 0.0,
            "must be finite and >= 0",
        )
    }
}

/// `Ok` when `value` is finite and `ok` holds, else [`ParamError::Invalid`] naming `key` and `why`.
/// Shared by the plant and protocol validators.
pub fn check(key: &'static str, value: f64, ok: bool, why: &'static str) -> Result<(), ParamError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(ParamError::Invalid { key, value, why })
    }
}

//! Model resolution: a `[[joint]]`'s friction model from its keys ([`model_spec`]), the `.fwt`
//! checks against the joint (gear ratio, joint name, k_t, stored input range), and whether the
//! backend can supply a PINN's inputs.

use std::path::Path;

use frictionless::features::{FeatureSpec, Signal};

use crate::ModelKind;
use crate::error::{Checker, ConfigError};
use crate::schema::{
    BackendKind, CanProtocol, JointConfig, ModelSpec, OodMode, RawConfig, ResolvedBus,
    StaticFallback,
};

/// Relative tolerance of the k_t comparison between a `.fwt` header and `[[joint]] kt`.
pub const KT_REL_TOLERANCE: f64 = 1e-6;

/// Reads and checks a `.fwt` model against its `[[joint]]`. Error text names the problem and both
/// values; the caller adds file and key.
///
/// The read accepts regular files only and runs the core's finite-output probe
/// ([`frictionless::weights::read_file`]). Then the model must match the joint: always the gear
/// ratio (sign and value, relative 1e-9: Δθ = r·s − θ), and the joint it was trained for: the file's
/// joint name must be the `[[joint]]`'s `name` and its k_t the joint's `kt` (relative
/// [`KT_REL_TOLERANCE`]: the labels were computed with it). A joint that deliberately runs another
/// joint's network (a template, as in `config/stress32.toml`) says so with `model_for = "<name in the
/// file>"`: the file's name is then compared with that, and k_t is not compared (the model's scale is
/// the other joint's). A file with an empty joint name (provenance unknown, e.g. an ONNX import without
/// `--joint`) is checked on the gear ratio and k_t only.
pub fn check_model_file(path: &Path, joint: &JointConfig) -> Result<(), String> {
    check_model(path, joint).map(|_| ())
}

/// What [`check_model`] learnt of a model file.
pub(crate) struct CheckedModel {
    /// The model's input features.
    features: FeatureSpec,
    /// Whether the file stores its training input range (the out-of-range check needs it).
    has_input_range: bool,
}

/// [`check_model_file`], returning what the rest of the config check needs of the model.
pub(crate) fn check_model(path: &Path, joint: &JointConfig) -> Result<CheckedModel, String> {
    let m = frictionless::weights::read_file(path).map_err(|e| e.to_string())?;
    let checked = CheckedModel {
        features: m.meta.features,
        has_input_range: m.meta.training.input_range.is_some(),
    };
    let r = m.meta.gear_ratio.get();
    let gear_ratio = joint.gear_ratio;
    if (r - gear_ratio).abs() > 1e-9 * gear_ratio.abs() {
        return Err(format!(
            "model was trained with gear_ratio {r}, config says {gear_ratio} (sign and value must match)"
        ));
    }
    let name = &m.meta.joint_name;
    if let Some(model_for) = &joint.model_for {
        if name != model_for {
            return Err(format!(
                "model is for joint {name:?}, config says model_for = {model_for:?}"
            ));
        }
        return Ok(checked);
    }
    let kt = m.meta.kt_nm_per_a;
    // Both are finite: the file's k_t is validated by the reader, the config's before this call.
    if (kt - joint.kt).abs() > KT_REL_TOLERANCE * joint.kt.abs() {
        return Err(format!(
            "model was trained with kt {kt} Nm/A, config says kt = {} Nm/A (the labels depend on it; must match within a relative {KT_REL_TOLERANCE:e}; a joint that runs another joint's model says so with model_for)",
            joint.kt
        ));
    }
    if !name.is_empty() && *name != joint.name {
        return Err(format!(
            "model is for joint {name:?}, config says name = {:?} (to run another joint's model, set model_for = {name:?})",
            joint.name
        ));
    }
    Ok(checked)
}

/// Where the daemon's value of one [`JointStates`](frictionless_shm_types::JointStates) field comes
/// from, for a joint on a given backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalSupply {
    /// Written by the shared-memory publisher (the robot's own software): whatever it measures; a
    /// field it does not have is NaN there, which the config cannot know.
    Publisher,
    /// Measured by the drive and decoded from its feedback frames.
    Measured,
    /// Computed from another measured field of the same drive (s = θ/r, ṡ = ω/r with the signed
    /// gear ratio r: the drive has only a motor-side encoder, so the transmission is taken as rigid).
    DerivedFrom(Signal),
    /// Not supplied: NaN in every tick.
    Absent,
}

impl std::fmt::Display for SignalSupply {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SignalSupply::Publisher => f.write_str("written by the shared-memory publisher"),
            SignalSupply::Measured => f.write_str("measured by the drive"),
            SignalSupply::DerivedFrom(from) => {
                write!(f, "derived from `{from}` (rigid transmission)")
            }
            SignalSupply::Absent => f.write_str("not supplied"),
        }
    }
}

/// What `backend` (and, for CAN, the bus's `protocol`) supplies for `signal`. The CAN protocols
/// report motor-side position and velocity (MIT reply: p, v, i; ODrive Get_Encoder_Estimates: pos,
/// vel in motor rev; CiA 402 TPDOs 0x6064, 0x606C) and, by protocol alone, no joint-side encoder or
/// temperature; a CiA 402 drive that maps them supplies more ([`cia402_signal_supply`]).
pub fn signal_supply(
    backend: BackendKind,
    protocol: Option<CanProtocol>,
    signal: Signal,
) -> SignalSupply {
    match (backend, protocol) {
        (BackendKind::Shm, _) | (BackendKind::Can, None) => SignalSupply::Publisher,
        (BackendKind::Can, Some(CanProtocol::Mit | CanProtocol::Odrive | CanProtocol::Cia402)) => {
            match signal {
                Signal::MotorPosRad | Signal::MotorVelRadS => SignalSupply::Measured,
                Signal::JointPosRad => SignalSupply::DerivedFrom(Signal::MotorPosRad),
                Signal::JointVelRadS => SignalSupply::DerivedFrom(Signal::MotorVelRadS),
                Signal::TemperatureC => SignalSupply::Absent,
            }
        }
    }
}

/// What a CiA 402 drive supplies: motor position and velocity always; the joint position measured
/// when its `joint_encoder` is mapped (else derived, s = θ/r); the temperature when mapped.
pub fn cia402_signal_supply(drive: &crate::schema::Cia402Drive, signal: Signal) -> SignalSupply {
    match signal {
        Signal::MotorPosRad | Signal::MotorVelRadS => SignalSupply::Measured,
        Signal::JointPosRad if drive.cfg.joint_encoder.is_some() => SignalSupply::Measured,
        Signal::JointPosRad => SignalSupply::DerivedFrom(Signal::MotorPosRad),
        Signal::JointVelRadS => SignalSupply::DerivedFrom(Signal::MotorVelRadS),
        Signal::TemperatureC if drive.cfg.temperature.is_some() => SignalSupply::Measured,
        Signal::TemperatureC => SignalSupply::Absent,
    }
}

/// Checks that the backend can supply every input of a PINN joint's model: each field the feature
/// spec reads must be supplied, and Δθ = r·s − θ needs a joint position that is not derived from the
/// motor encoder (derived, Δθ is the latched constant and carries no deflection). Returns the
/// message naming joint, set and field.
pub fn check_model_inputs(
    joint: &str,
    spec: &FeatureSpec,
    backend: BackendKind,
    protocol: Option<CanProtocol>,
) -> Result<(), String> {
    check_supply(joint, spec, where_name(backend, protocol), |s| {
        signal_supply(backend, protocol, s)
    })
}

fn where_name(backend: BackendKind, protocol: Option<CanProtocol>) -> &'static str {
    match (backend, protocol) {
        (BackendKind::Can, Some(CanProtocol::Mit)) => "the can backend (protocol = \"mit\")",
        (BackendKind::Can, Some(CanProtocol::Odrive)) => "the can backend (protocol = \"odrive\")",
        (BackendKind::Can, Some(CanProtocol::Cia402)) => {
            "the can backend (protocol = \"cia402\", this drive's PDO layout)"
        }
        (BackendKind::Can, None) => "the can backend",
        (BackendKind::Shm, _) => "the shm backend",
    }
}

/// [`check_model_inputs`] over a supply function.
fn check_supply(
    joint: &str,
    spec: &FeatureSpec,
    where_: &str,
    supply: impl Fn(Signal) -> SignalSupply,
) -> Result<(), String> {
    for signal in spec.required_signals() {
        if supply(signal) == SignalSupply::Absent {
            return Err(format!(
                "joint {joint}: feature set `{}` ({spec}) needs `{signal}`, which {where_} does not supply",
                spec.set
            ));
        }
    }
    if spec.set.uses_delta_theta()
        && let SignalSupply::DerivedFrom(from) = supply(Signal::JointPosRad)
    {
        return Err(format!(
            "joint {joint}: feature set `{}` ({spec}) needs `s_rad` from a joint-side encoder for Δθ = r·s − θ, but {where_} derives `s_rad` from `{from}` (s = θ/r): Δθ would be constant; use a set without Δθ (e.g. motor-vel-joint-vel, joint-pos-joint-vel)",
            spec.set
        ));
    }
    Ok(())
}

/// The joint's resolved model, and for a PINN the model file's input features. Keys in errors are
/// `{table}.{key}` (`joint[k]`, or `joint[k].alternate[m]` for an alternate's keys).
pub(crate) fn model_spec(
    c: &Checker,
    base: &Path,
    table: &str,
    j: &JointConfig,
) -> Result<(ModelSpec, Option<FeatureSpec>), ConfigError> {
    use frictionless::friction::{CvParams, ScvParams, StaticFriction};
    let keys = ModelKeys {
        c,
        table,
        model_name: j
            .friction_model
            .config_name()
            .unwrap_or(j.friction_model.name()),
    };
    match j.friction_model {
        ModelKind::ScvCode => Err(c.fail(
            keys.key("friction_model"),
            keys.model_name,
            "not a daemon model: the code form runs as coulomb_viscous_stribeck with ka = inf, alpha = 2",
        )),
        ModelKind::None => {
            keys.forbid(&[
                ("kc", j.kc.is_some()),
                ("kv", j.kv.is_some()),
                ("ka", j.ka.is_some()),
                ("ks", j.ks.is_some()),
                ("vs", j.vs.is_some()),
                ("alpha", j.alpha.is_some()),
                ("model", j.model.is_some()),
                ("sigma0", j.sigma0.is_some()),
                ("sigma1", j.sigma1.is_some()),
            ])?;
            Ok((ModelSpec::None, None))
        }
        ModelKind::Cv => {
            keys.forbid(&[
                ("ks", j.ks.is_some()),
                ("vs", j.vs.is_some()),
                ("alpha", j.alpha.is_some()),
                ("model", j.model.is_some()),
                ("sigma0", j.sigma0.is_some()),
                ("sigma1", j.sigma1.is_some()),
            ])?;
            let p = CvParams {
                kc: keys.need("kc", j.kc)?,
                ka: keys.need("ka", j.ka)?,
                kv: keys.need("kv", j.kv)?,
            };
            p.validate().map_err(|e| keys.param_err(e))?;
            Ok((ModelSpec::Cv(p), None))
        }
        ModelKind::Scv => {
            keys.forbid(&[
                ("model", j.model.is_some()),
                ("sigma0", j.sigma0.is_some()),
                ("sigma1", j.sigma1.is_some()),
            ])?;
            let p = ScvParams {
                kc: keys.need("kc", j.kc)?,
                ka: keys.need("ka", j.ka)?,
                kv: keys.need("kv", j.kv)?,
                ks: keys.need("ks", j.ks)?,
                vs: keys.need("vs", j.vs)?,
                alpha: keys.need("alpha", j.alpha)?,
            };
            p.validate().map_err(|e| keys.param_err(e))?;
            Ok((ModelSpec::Scv(p), None))
        }
        ModelKind::Lugre => {
            keys.forbid(&[("model", j.model.is_some()), ("ka", j.ka.is_some())])?;
            let p = frictionless::lugre::LugreParams {
                kc: keys.need("kc", j.kc)?,
                kv: keys.need("kv", j.kv)?,
                ks: keys.need("ks", j.ks)?,
                vs: keys.need("vs", j.vs)?,
                alpha: keys.need("alpha", j.alpha)?,
                sigma0: keys.need("sigma0", j.sigma0)?,
                sigma1: keys.need("sigma1", j.sigma1)?,
            };
            p.validate()
                .map_err(|e| c.fail(keys.key(e.name), e.value, e.requirement))?;
            Ok((ModelSpec::Lugre(p), None))
        }
        ModelKind::Pinn => pinn_spec(&keys, base, j),
    }
}

/// The keys of one model's table (`joint[k]` or `joint[k].alternate[m]`) as [`model_spec`] names
/// them in errors, with the rules every model kind shares: a key it needs, a key it does not use.
struct ModelKeys<'a> {
    c: &'a Checker<'a>,
    table: &'a str,
    /// `friction_model` as the file writes it.
    model_name: &'a str,
}

impl ModelKeys<'_> {
    /// `{table}.{name}`.
    fn key(&self, name: &str) -> String {
        format!("{}.{name}", self.table)
    }

    /// The value of key `name`, which the model kind requires.
    fn need(&self, name: &str, v: Option<f64>) -> Result<f64, ConfigError> {
        v.ok_or_else(|| {
            self.c.fail(
                self.key(name),
                "<missing>",
                &format!("required by friction_model = {:?}", self.model_name),
            )
        })
    }

    /// Refuses the first key of `names` that is present: the model kind does not use it.
    fn forbid(&self, names: &[(&str, bool)]) -> Result<(), ConfigError> {
        for (n, present) in names {
            if *present {
                return Err(self.c.fail(
                    self.key(n),
                    "<set>",
                    &format!("not used by friction_model = {:?}", self.model_name),
                ));
            }
        }
        Ok(())
    }

    /// A static model's parameter rule broken, named by its key.
    fn param_err(&self, e: frictionless::friction::FrictionParamError) -> ConfigError {
        match e {
            frictionless::friction::FrictionParamError::Invalid {
                name,
                value,
                requirement,
                ..
            } => self.c.fail(self.key(name), value, requirement),
            other => self
                .c
                .fail(self.key("friction_model"), "?", &other.to_string()),
        }
    }
}

/// `friction_model = "pinn"`: its static fallback ([`static_fallback`]), the model file checked
/// against the joint, and the file's input features.
fn pinn_spec(
    keys: &ModelKeys<'_>,
    base: &Path,
    j: &JointConfig,
) -> Result<(ModelSpec, Option<FeatureSpec>), ConfigError> {
    let c = keys.c;
    keys.forbid(&[
        ("sigma0", j.sigma0.is_some()),
        ("sigma1", j.sigma1.is_some()),
    ])?;
    let fallback = static_fallback(keys, j)?;
    let rel = j.model.as_ref().ok_or_else(|| {
        c.fail(
            keys.key("model"),
            "<missing>",
            "required by friction_model = \"pinn\"",
        )
    })?;
    let path = base.join(rel);
    let checked = check_model(&path, j).map_err(|message| ConfigError::Model {
        file: c.file.to_path_buf(),
        key: keys.key("model"),
        path: path.clone(),
        message,
    })?;
    if fallback.is_some() && !checked.has_input_range {
        return Err(c.fail(
            keys.key("ood"),
            "\"static\"",
            &format!(
                "needs a model that stores its training input range, and {} stores none: the out-of-range check never fires, so the static fallback could never engage (use ood = \"flag\" or \"off\", or a model trained with a recorded input range)",
                path.display()
            ),
        ));
    }
    let features = checked.features;
    Ok((
        ModelSpec::Pinn {
            path,
            warmup: j.warmup,
            fallback,
        },
        Some(features),
    ))
}

/// A PINN joint's static model: with `ood = "static"` kc, ka, kv (CV) and, if any of ks, vs, alpha
/// is given, all three (SCV); otherwise none, and no static key may be set.
fn static_fallback(
    keys: &ModelKeys<'_>,
    j: &JointConfig,
) -> Result<Option<StaticFallback>, ConfigError> {
    use frictionless::friction::{CvParams, ScvParams, StaticFriction};
    if j.ood != OodMode::Static {
        keys.forbid(&[
            ("kc", j.kc.is_some()),
            ("kv", j.kv.is_some()),
            ("ka", j.ka.is_some()),
            ("ks", j.ks.is_some()),
            ("vs", j.vs.is_some()),
            ("alpha", j.alpha.is_some()),
        ])?;
        return Ok(None);
    }
    let need_static = |name: &str, v: Option<f64>| {
        v.ok_or_else(|| {
            keys.c.fail(
                keys.key(name),
                "<missing>",
                "required by ood = \"static\" (the static model of a PINN joint)",
            )
        })
    };
    let (kc, ka, kv) = (
        need_static("kc", j.kc)?,
        need_static("ka", j.ka)?,
        need_static("kv", j.kv)?,
    );
    Ok(Some(
        if j.ks.is_some() || j.vs.is_some() || j.alpha.is_some() {
            let p = ScvParams {
                kc,
                ka,
                kv,
                ks: need_static("ks", j.ks)?,
                vs: need_static("vs", j.vs)?,
                alpha: need_static("alpha", j.alpha)?,
            };
            p.validate().map_err(|e| keys.param_err(e))?;
            StaticFallback::Scv(p)
        } else {
            let p = CvParams { kc, ka, kv };
            p.validate().map_err(|e| keys.param_err(e))?;
            StaticFallback::Cv(p)
        },
    ))
}

/// A PINN model of the config (a joint's own or an alternate) whose inputs the backend must supply.
pub(crate) struct PinnInputs {
    /// Position of the joint in `raw.joint`.
    pub joint_pos: usize,
    /// The key naming the model file (`joint[k].model`, `joint[k].alternate[m].model`).
    pub key: String,
    /// The resolved model file.
    pub path: std::path::PathBuf,
    /// Its input features.
    pub features: FeatureSpec,
}

/// Every PINN's inputs must be suppliable by its joint's backend (and, on CAN, its bus protocol):
/// [`check_model_inputs`] per PINN model, the error naming its `model` key.
pub(crate) fn check_pinn_inputs(
    c: &Checker,
    raw: &RawConfig,
    pinns: &[PinnInputs],
    buses: &[ResolvedBus],
) -> Result<(), ConfigError> {
    for p in pinns {
        let j = &raw.joint[p.joint_pos];
        let spec = &p.features;
        let on_bus = buses.iter().find_map(|b| {
            b.joints
                .iter()
                .find(|d| d.index == j.index)
                .map(|d| (b.protocol, d.cia402))
        });
        let protocol = on_bus.map(|(p, _)| p);
        let checked = match on_bus {
            Some((_, Some(drive))) => {
                check_supply(&j.name, spec, where_name(raw.backend.kind, protocol), |s| {
                    cia402_signal_supply(&drive, s)
                })
            }
            _ => check_model_inputs(&j.name, spec, raw.backend.kind, protocol),
        };
        if let Err(message) = checked {
            return Err(ConfigError::Model {
                file: c.file.to_path_buf(),
                key: p.key.clone(),
                path: p.path.clone(),
                message,
            });
        }
    }
    Ok(())
}

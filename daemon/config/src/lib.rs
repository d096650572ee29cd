//! `frictiond-config`: frictiond's TOML configuration — the typed schema, its validation, the
//! resolved per-joint and per-bus parameters, and the runtime parameters built from them ([`params`]).
//!
//! What this crate **is**: one TOML file (`serde` + `toml`, unknown keys are errors) describing the loop
//! (`[loop]`), the I/O backend (`[backend]`), safety behaviour (`[safety]`), the joints
//! (`[[joint]]`, key names after the ergoCub `JointTorqueControlDevice`: `kt`, `kfc`, `kp`, `ki`,
//! `max_curr`, `max_output_friction`, `friction_model`, `kc`, `kv`, `ka`, `ks`, `vs`, `alpha`, `model`;
//! ours: `warmup`, `delta_theta_offset_motor_rad`) and the CAN buses (`[[bus]]`).
//! [`RawConfig`] is the file as written; it is `Serialize` too, so tools write configs with
//! `toml::to_string` instead of formatting TOML by hand. [`load`] / [`parse`] run the validation that
//! `frictiond --check` runs (including reading every model file) and return a [`Config`] or a
//! [`ConfigError`] naming the file, the key and the value.
//!
//! [`params::build`] turns a [`Config`] into what frictiond's RT thread runs: per-joint estimators
//! (models read from their files), control laws and filter coefficients, allocated here, off the RT
//! thread.
//!
//! What it is **not**: no IPC, no threads, no I/O besides reading the config and model files. Used by `frictiond` and by `frictl`; it depends on
//! neither. Units: SI, joint side; the velocity threshold is in **rad/s** (BLF used deg/s).
//!
//! ## Example: parse, read resolved values, write back with `toml::to_string`
//! ```
//! use std::path::Path;
//! use frictiond_config::{LpfConfig, ModelSpec};
//!
//! // One CV joint: no model file needed. The path only names the file in errors (and resolves
//! // relative model paths); nothing is read.
//! let text = r#"
//! [backend]
//! kind = "shm"
//!
//! [[joint]]
//! name = "knee"
//! index = 0
//! gear_ratio = -100.0   # signed: motor angle = r · joint angle
//! kt = 0.157            # Nm/A
//! max_curr = 5.0        # A
//! friction_model = "coulomb_viscous"
//! kc = 8.1
//! ka = 50.84
//! kv = 5.55
//! "#;
//! let cfg = frictiond_config::parse(Path::new("/etc/frictiond/knee.toml"), text)?;
//! assert_eq!(cfg.period_ns(), 1_000_000, "[loop] defaults to 1 kHz");
//! assert_eq!(cfg.raw.joint[0].kfc, 1.0, "kfc defaults to 1");
//! let ModelSpec::Cv(cv) = &cfg.models[0] else { panic!("coulomb_viscous resolves to CV") };
//! assert_eq!((cv.kc, cv.ka, cv.kv), (8.1, 50.84, 5.55));
//!
//! // Tools write configs through the same types: serialize, edit, re-parse (and re-validate).
//! let mut raw = cfg.raw.clone();
//! raw.joint[0].kfc = 0.85;
//! raw.joint[0].lpf = Some(LpfConfig { order: 2, cutoff_hz: 10.0 });
//! let written = toml::to_string(&raw)?;
//! let back = frictiond_config::parse(Path::new("/tmp/written.toml"), &written)?;
//! assert_eq!(back.raw, raw);
//! assert_eq!(back.models, cfg.models);
//!
//! // Errors name the file, the key and the value.
//! let bad = text.replace("kt = 0.157", "kt = -0.157");
//! let err = frictiond_config::parse(Path::new("/etc/frictiond/knee.toml"), &bad).unwrap_err();
//! assert!(err.to_string().contains("joint[0].kt"), "{err}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

mod buses;
mod error;
mod models;
pub mod params;
pub mod runtime;
mod schema;
#[cfg(test)]
mod tests;
mod validate;

use std::path::Path;

pub use buses::bus_summary;
pub use error::ConfigError;
pub use frictionless::model::ModelKind;
pub use frictionless_drives::can::units::CommandUnit;
pub use models::{
    KT_REL_TOLERANCE, SignalSupply, check_model_file, check_model_inputs, cia402_signal_supply,
    signal_supply,
};
pub use schema::*;
pub use validate::{MAX_MODEL_NAME_BYTES, MAX_TICK_SPAN_S, alternate_name_rule};

use buses::resolve_buses;
use error::Checker;
use models::check_pinn_inputs;
use validate::{check_backend, check_joints, check_loop, check_tick_counts};

/// Reads, parses and validates `path`, including every model file. Touches no IPC.
pub fn load(path: &Path) -> Result<Config, ConfigError> {
    let text = frictionless::regular_file::read_text(path).map_err(|source| ConfigError::Read {
        file: path.to_path_buf(),
        source,
    })?;
    parse(path, &text)
}

/// Parses and validates `text` as if read from `path` (relative model paths resolve against its
/// directory).
pub fn parse(path: &Path, text: &str) -> Result<Config, ConfigError> {
    let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
        file: path.to_path_buf(),
        message: e.to_string().trim_end().replace('\n', " | "),
    })?;
    let c = Checker { file: path };
    let base = path.parent().unwrap_or(Path::new("."));
    check_loop(&c, &raw.loop_)?;
    check_tick_counts(&c, &raw)?;
    check_backend(&c, &raw, base)?;
    let (models, alternates, pinns) = check_joints(&c, &raw, base)?;
    let fs_hz = 1e6 / raw.loop_.period_us as f64;
    let buses = resolve_buses(&c, &raw, fs_hz)?;
    check_pinn_inputs(&c, &raw, &pinns, &buses)?;
    let root_path = raw.backend.root_path.as_ref().map(|p| base.join(p));
    Ok(Config {
        file: path.to_path_buf(),
        raw,
        models,
        alternates,
        root_path,
        buses,
    })
}

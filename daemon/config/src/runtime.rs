//! Runtime changes of a running daemon's joint values: a `KEY=VALUE` request checked by the same
//! rules as the file (the rules are defined here once and `validate::check_joint` calls them), the
//! checked [`RuntimeSet`] handed to the RT thread, and [`JointRt::apply`], which the RT thread
//! calls at a tick boundary.
//!
//! What this module **is**: the keys a running daemon accepts (`kfc`, `max_output_friction`,
//! `max_curr`, `compensation`, `ood`, named as in the config, and `model`: which of the joint's
//! preloaded models runs, [`model_names`]), their rules, and the allocation-free application to
//! one joint's runtime parameters.
//!
//! What it is **not**: no IPC, no threads (the transport and the hand-over are frictiond's).
//!
//! Precedence: a runtime value lives in the parameter set it was applied to. A reload builds a new
//! set from the file, so it drops every runtime value; a set checked against the parameter
//! generation before a reload is dropped by the RT thread, not applied to the new one
//! ([`RuntimeSet::generation`]).

use crate::ModelKind;
use crate::schema::{JointConfig, MODEL_NAME_DEFAULT, MODEL_NAME_NONE, OodMode};
use crate::{Config, ModelSpec};

use crate::params::JointRt;

/// The rule of `kfc`: in [0, 2].
pub fn kfc_rule(v: f64) -> Result<(), &'static str> {
    if v.is_finite() && (0.0..=2.0).contains(&v) {
        Ok(())
    } else {
        Err("must be in [0, 2]")
    }
}

/// The rule of `max_output_friction` [Nm]: > 0 (`inf` = never clipped).
pub fn max_output_friction_rule(v: f64) -> Result<(), &'static str> {
    if v.is_nan() || v <= 0.0 {
        Err("must be > 0")
    } else {
        Ok(())
    }
}

/// The rule of `max_curr` [A]: finite and > 0.
pub fn max_curr_rule(v: f64) -> Result<(), &'static str> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err("must be finite and > 0")
    }
}

/// The runtime rule of `ood = "static"`: the joint's static model was resolved at load, which the
/// file does for a PINN joint with `ood = "static"` (`has_fallback`).
pub fn ood_rule(mode: OodMode, has_fallback: bool) -> Result<(), &'static str> {
    if mode == OodMode::Static && !has_fallback {
        Err(
            "only a PINN joint whose file sets ood = \"static\" (its static model resolved at load) can fall back at run time",
        )
    } else {
        Ok(())
    }
}

/// One change of one joint's value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    /// `kfc`.
    Kfc(f64),
    /// `max_output_friction` [Nm].
    MaxOutputFriction(f64),
    /// `max_curr` [A] (≤ the file's value).
    MaxCurr(f64),
    /// `compensation = on|off`.
    Compensation(bool),
    /// `ood`.
    Ood(OodMode),
    /// `model`: the slot of [`model_names`] to run.
    Model(usize),
}

/// The names of the models joint `pos` of `cfg` can run, by slot: `default` (its own
/// `friction_model`), its `[[joint.alternate]]`s in file order, `none`. The RT thread's
/// [`crate::params::ModelSlots`] holds them in this order.
pub fn model_names(cfg: &Config, pos: usize) -> Vec<&str> {
    let alternates = cfg.alternates.get(pos).map(Vec::as_slice).unwrap_or(&[]);
    std::iter::once(MODEL_NAME_DEFAULT)
        .chain(alternates.iter().map(|a| a.name.as_str()))
        .chain(std::iter::once(MODEL_NAME_NONE))
        .collect()
}

/// The kind of slot `slot` of joint `pos` ([`model_names`]' order) as the daemon runs it.
pub fn model_kind(cfg: &Config, pos: usize, slot: usize) -> ModelKind {
    let alternates = cfg.alternates.get(pos).map(Vec::as_slice).unwrap_or(&[]);
    match slot {
        0 => cfg
            .raw
            .joint
            .get(pos)
            .map_or(ModelKind::None, |j| j.friction_model.daemon_kind()),
        s if s <= alternates.len() => alternates[s - 1].kind,
        _ => ModelKind::None,
    }
}

impl Change {
    /// The config key the change sets.
    pub fn key(&self) -> &'static str {
        match self {
            Self::Kfc(_) => "kfc",
            Self::MaxOutputFriction(_) => "max_output_friction",
            Self::MaxCurr(_) => "max_curr",
            Self::Compensation(_) => "compensation",
            Self::Ood(_) => "ood",
            Self::Model(_) => "model",
        }
    }
}

/// The keys [`check`] accepts, as the config names them.
pub const RUNTIME_KEYS: [&str; 6] = [
    "kfc",
    "max_output_friction",
    "max_curr",
    "compensation",
    "ood",
    "model",
];

/// A checked change for the RT thread: `Copy`, no heap, so handing it over allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RuntimeSet {
    /// The parameter generation it was checked against; the RT thread drops it if another set is
    /// in use (a reload came in between).
    pub generation: u64,
    /// The joint's payload index (`[[joint]] index`).
    pub joint_index: usize,
    /// What changes.
    pub change: Change,
}

/// Why a runtime request was refused: the joint, the key, the value as sent and the rule.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("joint `{joint}`: `{key}` = {value}: {rule}")]
pub struct Refusal {
    /// The joint as named in the request.
    pub joint: String,
    /// The key as sent.
    pub key: String,
    /// The value as sent.
    pub value: String,
    /// The rule it breaks.
    pub rule: String,
}

/// Checks `key = value` for `joint` against `cfg` (the file in use, generation `generation`) by
/// the file's rules, plus one of its own: a runtime `max_curr` may lower the file's clamp, never
/// raise it (a CAN drive was opened with the file's). Values are written as in the config: numbers,
/// `on`/`off` (or `true`/`false`) for `compensation`, `off`/`flag`/`static` for `ood`, a name of
/// [`model_names`] for `model` (an unknown one is refused with the list).
pub fn check(
    cfg: &Config,
    generation: u64,
    joint: &str,
    key: &str,
    value: &str,
) -> Result<RuntimeSet, Refusal> {
    let refuse = |rule: &str| Refusal {
        joint: joint.to_owned(),
        key: key.to_owned(),
        value: value.to_owned(),
        rule: rule.to_owned(),
    };
    let Some(pos) = cfg.raw.joint.iter().position(|j| j.name == joint) else {
        let names: Vec<&str> = cfg.raw.joint.iter().map(|j| j.name.as_str()).collect();
        return Err(refuse(&format!(
            "no such joint (configured: {})",
            names.join(", ")
        )));
    };
    let j: &JointConfig = &cfg.raw.joint[pos];
    let number = || {
        value
            .trim()
            .parse::<f64>()
            .map_err(|_| refuse("must be a number"))
    };
    let change = match key {
        "kfc" => {
            let v = number()?;
            kfc_rule(v).map_err(refuse)?;
            Change::Kfc(v)
        }
        "max_output_friction" => {
            let v = number()?;
            max_output_friction_rule(v).map_err(refuse)?;
            Change::MaxOutputFriction(v)
        }
        "max_curr" => {
            let v = number()?;
            max_curr_rule(v).map_err(refuse)?;
            if v > j.max_curr {
                return Err(refuse(&format!(
                    "must be <= the file's max_curr ({}): a running daemon lowers the clamp, never raises it",
                    j.max_curr
                )));
            }
            Change::MaxCurr(v)
        }
        "compensation" => match value.trim() {
            "on" | "true" => Change::Compensation(true),
            "off" | "false" => Change::Compensation(false),
            _ => return Err(refuse("must be on or off")),
        },
        "ood" => {
            let mode = match value.trim().trim_matches('"') {
                "off" => OodMode::Off,
                "flag" => OodMode::Flag,
                "static" => OodMode::Static,
                _ => return Err(refuse("must be off, flag or static")),
            };
            let has_fallback = matches!(
                cfg.models.get(pos),
                Some(ModelSpec::Pinn {
                    fallback: Some(_),
                    ..
                })
            );
            ood_rule(mode, has_fallback).map_err(refuse)?;
            Change::Ood(mode)
        }
        "model" => {
            let name = value.trim().trim_matches('"');
            let names = model_names(cfg, pos);
            match names.iter().position(|&n| n == name) {
                Some(slot) => Change::Model(slot),
                None => {
                    return Err(refuse(&format!(
                        "no such model of this joint (available: {})",
                        names.join(", ")
                    )));
                }
            }
        }
        _ => {
            return Err(refuse(&format!(
                "not a runtime key (keys: {})",
                RUNTIME_KEYS.join(", ")
            )));
        }
    };
    Ok(RuntimeSet {
        generation,
        joint_index: j.index,
        change,
    })
}

impl JointRt {
    /// Applies a checked change (RT thread, at a tick boundary: no allocation, no lock, no
    /// panic). Gains take effect in the next [`frictionless::law::JointLaw::step`]; the filter and
    /// integral state are kept. `compensation = off` feeds the law 0 friction (the model keeps
    /// running, so switching on needs no warm-up); `ood` restarts the blend from the joint's own
    /// model; `model` makes another preloaded model active ([`JointRt::switch_model`]).
    #[inline]
    pub fn apply(&mut self, change: Change) {
        match change {
            Change::Kfc(v) => self.law.gains.kfc = v,
            Change::MaxOutputFriction(v) => self.law.gains.max_output_friction_nm = v,
            Change::MaxCurr(v) => self.law.gains.max_curr_a = v,
            Change::Compensation(on) => self.compensation = on,
            Change::Ood(mode) => {
                self.ood.mode = mode;
                self.ood.reset();
            }
            Change::Model(slot) => self.switch_model(slot),
        }
    }
}

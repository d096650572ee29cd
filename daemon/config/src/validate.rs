//! Validation of the sections that stand on their own: `[loop]`, the tick counts, `[backend]` and
//! each `[[joint]]`'s keys. Models are resolved in `models`, buses in `buses`; the error type and
//! the [`Checker`] that names file, key and value are `error`'s.

use std::path::Path;

use frictionless_shm_types::MAX_JOINTS;

use crate::ModelKind;
use crate::error::{Checker, ConfigError};
use crate::models::{PinnInputs, model_spec};
use crate::runtime;
use crate::schema::{
    JointConfig, LoopConfig, MODEL_NAME_DEFAULT, MODEL_NAME_NONE, ModelSpec, MotorEncoder,
    NamedModel, OodMode, Prefetch, RawConfig,
};

/// The online CPUs as the kernel lists them in `/sys/devices/system/cpu/online` (none when the file
/// cannot be read or parsed, e.g. without `/sys`).
pub(crate) fn online_cpus() -> Option<Vec<std::ops::RangeInclusive<usize>>> {
    parse_cpu_list(&std::fs::read_to_string("/sys/devices/system/cpu/online").ok()?)
}

/// Parses a kernel CPU list such as `0-3,6,8-9`.
pub(crate) fn parse_cpu_list(text: &str) -> Option<Vec<std::ops::RangeInclusive<usize>>> {
    let mut out = Vec::new();
    for part in text.trim().split(',') {
        let (a, b) = part.split_once('-').unwrap_or((part, part));
        let (a, b) = (a.parse().ok()?, b.parse().ok()?);
        if a > b {
            return None;
        }
        out.push(a..=b);
    }
    Some(out)
}

/// Longest run of ticks `ready_after_ticks` and `stale_after_ticks` may span [s].
pub const MAX_TICK_SPAN_S: u64 = 60;

/// `cpu`-like keys: below `CPU_SETSIZE` and in the machine's online set.
pub(crate) fn check_cpu(c: &Checker<'_>, key: &str, cpu: usize) -> Result<(), ConfigError> {
    let setsize = libc::CPU_SETSIZE as usize;
    if cpu >= setsize {
        return Err(c.fail(
            key.into(),
            cpu,
            &format!("must be below CPU_SETSIZE ({setsize}) and an online CPU"),
        ));
    }
    if let Some(online) = online_cpus()
        && !online.iter().any(|r| r.contains(&cpu))
    {
        let list: Vec<String> = online
            .iter()
            .map(|r| {
                if r.start() == r.end() {
                    r.start().to_string()
                } else {
                    format!("{}-{}", r.start(), r.end())
                }
            })
            .collect();
        return Err(c.fail(
            key.into(),
            cpu,
            &format!(
                "must be an online CPU (online: {}, /sys/devices/system/cpu/online)",
                list.join(",")
            ),
        ));
    }
    Ok(())
}

/// `[loop]` on its own: period, priority, PM QoS, CPUs, RT threads, prefetch lead.
pub(crate) fn check_loop(c: &Checker, l: &LoopConfig) -> Result<(), ConfigError> {
    if !(20..=1_000_000).contains(&l.period_us) {
        return Err(c.fail("loop.period_us".into(), l.period_us, "must be 20..=1000000"));
    }
    if let Some(p) = l.priority
        && !(1..=99).contains(&p)
    {
        return Err(c.fail("loop.priority".into(), p, "must be 1..=99 (SCHED_FIFO)"));
    }
    if let Some(us) = l.cpu_dma_latency_us
        && us > i32::MAX as u32
    {
        return Err(c.fail(
            "loop.cpu_dma_latency_us".into(),
            us,
            "must fit the kernel's s32 PM QoS value (0..=2147483647)",
        ));
    }
    if let Some(cpu) = l.cpu {
        check_cpu(c, "loop.cpu", cpu)?;
    }
    if !(1..=2).contains(&l.rt_threads) {
        return Err(c.fail(
            "loop.rt_threads".into(),
            l.rt_threads,
            "must be 1 or 2 (RT threads computing a tick)",
        ));
    }
    if let Some(cpu) = l.helper_cpu {
        if l.rt_threads != 2 {
            return Err(c.fail(
                "loop.helper_cpu".into(),
                cpu,
                "only with rt_threads = 2 (there is no helper thread to pin)",
            ));
        }
        check_cpu(c, "loop.helper_cpu", cpu)?;
        if l.cpu == Some(cpu) {
            return Err(c.fail(
                "loop.helper_cpu".into(),
                cpu,
                "must differ from loop.cpu (the main RT thread waits for the helper; on one CPU at the same SCHED_FIFO priority it would never run)",
            ));
        }
    }
    if l.prefetch == Prefetch::Lead && !(1..l.period_us).contains(&l.prefetch_lead_us) {
        return Err(c.fail(
            "loop.prefetch_lead_us".into(),
            l.prefetch_lead_us,
            &format!(
                "must be 1..{} (below period_us) with prefetch = \"lead\"",
                l.period_us
            ),
        ));
    }
    Ok(())
}

/// The tick counts of `[loop]` and `[safety]`: bounded in time ([`MAX_TICK_SPAN_S`]) and >= 1.
pub(crate) fn check_tick_counts(c: &Checker, raw: &RawConfig) -> Result<(), ConfigError> {
    let l = &raw.loop_;
    let max_ticks = MAX_TICK_SPAN_S * 1_000_000 / l.period_us;
    if l.ready_after_ticks > max_ticks {
        return Err(c.fail(
            "loop.ready_after_ticks".into(),
            l.ready_after_ticks,
            &format!(
                "must be <= {max_ticks} ({MAX_TICK_SPAN_S} s at period_us = {})",
                l.period_us
            ),
        ));
    }
    if raw.safety.stale_after_ticks > max_ticks {
        return Err(c.fail(
            "safety.stale_after_ticks".into(),
            raw.safety.stale_after_ticks,
            &format!(
                "must be <= {max_ticks} ({MAX_TICK_SPAN_S} s at period_us = {})",
                l.period_us
            ),
        ));
    }
    if l.status_every_ticks == 0 {
        return Err(c.fail("loop.status_every_ticks".into(), 0, "must be >= 1"));
    }
    if raw.safety.stale_after_ticks == 0 {
        return Err(c.fail("safety.stale_after_ticks".into(), 0, "must be >= 1"));
    }
    Ok(())
}

/// `[backend]`: the service prefix and the iceoryx2 root path (resolved against `base`).
pub(crate) fn check_backend(c: &Checker, raw: &RawConfig, base: &Path) -> Result<(), ConfigError> {
    if raw.backend.service_prefix.is_empty() || raw.backend.service_prefix.contains('\0') {
        return Err(c.fail(
            "backend.service_prefix".into(),
            format!("{:?}", raw.backend.service_prefix),
            "must be non-empty without NUL",
        ));
    }
    let prefix = &raw.backend.service_prefix;
    let max_prefix = frictionless_shm_types::MAX_SERVICE_PREFIX_BYTES;
    if prefix.len() > max_prefix {
        let head: String = prefix.chars().take(32).collect();
        return Err(c.fail(
            "backend.service_prefix".into(),
            format!("{head:?}… ({} bytes)", prefix.len()),
            &format!(
                "must be at most {max_prefix} bytes (iceoryx2 service names are at most 255 bytes, and `/motor_current_command` is appended)"
            ),
        ));
    }
    if prefix.starts_with("iox2://") {
        return Err(c.fail(
            "backend.service_prefix".into(),
            format!("{prefix:?}"),
            "must not start with `iox2://` (reserved by iceoryx2)",
        ));
    }
    if let Some(root) = &raw.backend.root_path {
        let resolved = base.join(root);
        if let Ok(m) = std::fs::metadata(&resolved)
            && !m.is_dir()
        {
            return Err(c.fail(
                "backend.root_path".into(),
                resolved.display(),
                "exists and is not a directory (iceoryx2 creates its files under it)",
            ));
        }
    }
    Ok(())
}

/// What [`check_joints`] resolves: per joint its model and its alternates, and every PINN model
/// whose inputs the backend must supply.
pub(crate) type CheckedJoints = (Vec<ModelSpec>, Vec<Vec<NamedModel>>, Vec<PinnInputs>);

/// The `[[joint]]` table: its size, then per joint its keys ([`check_joint`]), its model
/// ([`model_spec`]) and its `[[joint.alternate]]`s (the same rules, keys named
/// `joint[k].alternate[m].KEY`).
pub(crate) fn check_joints(
    c: &Checker,
    raw: &RawConfig,
    base: &Path,
) -> Result<CheckedJoints, ConfigError> {
    if raw.joint.is_empty() {
        return Err(c.fail("joint".into(), "[]", "at least one [[joint]] is required"));
    }
    if raw.joint.len() > MAX_JOINTS {
        return Err(c.fail(
            "joint".into(),
            raw.joint.len(),
            &format!("at most {MAX_JOINTS} joints"),
        ));
    }
    let fs_hz = 1e6 / raw.loop_.period_us as f64;
    let mut models = Vec::with_capacity(raw.joint.len());
    let mut alternates = Vec::with_capacity(raw.joint.len());
    let mut pinns = Vec::new();
    for (k, j) in raw.joint.iter().enumerate() {
        check_joint(c, raw, k, j, fs_hz)?;
        let table = format!("joint[{k}]");
        let (model, features) = model_spec(c, base, &table, j)?;
        if let (ModelSpec::Pinn { path, .. }, Some(features)) = (&model, features) {
            pinns.push(PinnInputs {
                joint_pos: k,
                key: format!("{table}.model"),
                path: path.clone(),
                features,
            });
        }
        models.push(model);
        let mut named: Vec<NamedModel> = Vec::with_capacity(j.alternate.len());
        for (m, a) in j.alternate.iter().enumerate() {
            let table = format!("joint[{k}].alternate[{m}]");
            if let Err(rule) = alternate_name_rule(&a.name) {
                return Err(c.fail(format!("{table}.name"), format!("{:?}", a.name), rule));
            }
            if named.iter().any(|n| n.name == a.name) {
                return Err(c.fail(
                    format!("{table}.name"),
                    format!("{:?}", a.name),
                    &format!("must be unique among joint {:?}'s alternates", j.name),
                ));
            }
            let (spec, features) = model_spec(c, base, &table, &a.as_joint(j))?;
            if let (ModelSpec::Pinn { path, .. }, Some(features)) = (&spec, features) {
                pinns.push(PinnInputs {
                    joint_pos: k,
                    key: format!("{table}.model"),
                    path: path.clone(),
                    features,
                });
            }
            named.push(NamedModel {
                name: a.name.clone(),
                spec,
                kind: a.friction_model.daemon_kind(),
            });
        }
        alternates.push(named);
    }
    Ok((models, alternates, pinns))
}

/// Most bytes of a `[[joint.alternate]] name` (it travels in a control request's text field).
pub const MAX_MODEL_NAME_BYTES: usize = frictionless_shm_types::control::CONTROL_TEXT_BYTES - 1;

/// The rule of `[[joint.alternate]] name`: 1–[`MAX_MODEL_NAME_BYTES`] bytes of `A-Z a-z 0-9 _ - .`,
/// not one of the reserved names `default` (the joint's own model) and `none`.
pub fn alternate_name_rule(name: &str) -> Result<(), &'static str> {
    if name.is_empty()
        || name.len() > MAX_MODEL_NAME_BYTES
        || !name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_-.".contains(&b))
    {
        Err("must be 1-63 bytes of A-Z a-z 0-9 _ - .")
    } else if name == MODEL_NAME_DEFAULT || name == MODEL_NAME_NONE {
        Err("`default` (the joint's own model) and `none` (no friction) are reserved")
    } else {
        Ok(())
    }
}

/// A rule's verdict on `key = value` as a [`ConfigError`] (the rules are in [`crate::runtime`],
/// shared with the runtime requests).
fn rule(
    c: &Checker,
    key: String,
    value: f64,
    verdict: Result<(), &'static str>,
) -> Result<(), ConfigError> {
    verdict.map_err(|req| c.fail(key, value, req))
}

/// `joint[k].speed_current_limit` as the law's limit (none when absent); a broken rule names its
/// key, value and the rule (`frictionless::law::SpeedCurrentLimit::new`'s).
pub(crate) fn speed_current_limit(
    c: &Checker,
    k: usize,
    j: &JointConfig,
) -> Result<Option<frictionless::law::SpeedCurrentLimit>, ConfigError> {
    let Some(l) = j.speed_current_limit else {
        return Ok(None);
    };
    frictionless::law::SpeedCurrentLimit::new(
        l.rated_motor_speed_rad_s,
        l.no_load_motor_speed_rad_s,
        l.safety_factor,
    )
    .map(Some)
    .map_err(|rule| {
        let value = match rule.field {
            "rated_motor_speed_rad_s" => l.rated_motor_speed_rad_s,
            "no_load_motor_speed_rad_s" => l.no_load_motor_speed_rad_s,
            _ => l.safety_factor,
        };
        c.fail(
            format!("joint[{k}].speed_current_limit.{}", rule.field),
            value,
            rule.rule,
        )
    })
}

/// The keys of `joint[k]` that do not depend on its model (name, index, gains, limits, filter,
/// out-of-range settings); `fs_hz` is the loop rate.
pub(crate) fn check_joint(
    c: &Checker,
    raw: &RawConfig,
    k: usize,
    j: &JointConfig,
    fs_hz: f64,
) -> Result<(), ConfigError> {
    let key = |name: &str| format!("joint[{k}].{name}");
    if j.name.is_empty() {
        return Err(c.fail(key("name"), "\"\"", "must be non-empty"));
    }
    if raw.joint[..k].iter().any(|o| o.name == j.name) {
        return Err(c.fail(key("name"), &j.name, "duplicate joint name"));
    }
    if j.index >= MAX_JOINTS {
        return Err(c.fail(key("index"), j.index, &format!("must be < {MAX_JOINTS}")));
    }
    if raw.joint[..k].iter().any(|o| o.index == j.index) {
        return Err(c.fail(key("index"), j.index, "duplicate joint index"));
    }
    if frictionless::units::GearRatio::new(j.gear_ratio).is_err() {
        return Err(c.fail(
            key("gear_ratio"),
            j.gear_ratio,
            "must be finite and non-zero",
        ));
    }
    c.finite_pos(key("kt"), j.kt)?;
    rule(
        c,
        key("max_curr"),
        j.max_curr,
        runtime::max_curr_rule(j.max_curr),
    )?;
    speed_current_limit(c, k, j)?;
    rule(c, key("kfc"), j.kfc, runtime::kfc_rule(j.kfc))?;
    c.nonneg(key("kp"), j.kp)?;
    c.nonneg(key("ki"), j.ki)?;
    rule(
        c,
        key("max_output_friction"),
        j.max_output_friction,
        runtime::max_output_friction_rule(j.max_output_friction),
    )?;
    c.nonneg(
        key("joint_velocity_threshold_rad_s"),
        j.joint_velocity_threshold_rad_s,
    )?;
    if let Some(off) = j.delta_theta_offset_motor_rad
        && !off.is_finite()
    {
        return Err(c.fail(key("delta_theta_offset_motor_rad"), off, "must be finite"));
    }
    if let Some(off) = j.delta_theta_offset_motor_rad
        && j.motor_encoder == MotorEncoder::Incremental
    {
        return Err(c.fail(
            key("delta_theta_offset_motor_rad"),
            off,
            "is a fixed encoder zero, but motor_encoder = \"incremental\" has a new zero at every power-up: remove the key (Δθ is then latched at every enable) and use a model trained with `frictl train --motor-encoder incremental`",
        ));
    }
    if let Some(lpf) = j.lpf {
        if !(1..=8).contains(&lpf.order) {
            return Err(c.fail(key("lpf.order"), lpf.order, "must be 1..=8"));
        }
        if !(lpf.cutoff_hz.is_finite() && lpf.cutoff_hz > 0.0 && lpf.cutoff_hz < 0.5 * fs_hz) {
            return Err(c.fail(
                key("lpf.cutoff_hz"),
                lpf.cutoff_hz,
                &format!("must be > 0 and below Nyquist ({} Hz)", 0.5 * fs_hz),
            ));
        }
    }
    if !(j.ood_margin.is_finite() && (0.0..=10.0).contains(&j.ood_margin)) {
        return Err(c.fail(key("ood_margin"), j.ood_margin, "must be in [0, 10]"));
    }
    if !(j.ood_ramp_ms.is_finite() && (0.0..=1000.0).contains(&j.ood_ramp_ms)) {
        return Err(c.fail(key("ood_ramp_ms"), j.ood_ramp_ms, "must be in [0, 1000] ms"));
    }
    if j.ood == OodMode::Static && j.friction_model != ModelKind::Pinn {
        return Err(c.fail(
            key("ood"),
            "\"static\"",
            "only a PINN joint can fall back to a static model",
        ));
    }
    Ok(())
}

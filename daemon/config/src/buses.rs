//! The CAN buses: `[[bus]]` checked against `[backend]` and the joints, each drive resolved
//! (node id, units, MIT ranges), the worst-case bus load, and the `--check` summary.

use frictionless_drives::can::busload;
use frictionless_drives::can::cia402::{Layout, PdoEntry};
use frictionless_drives::can::mit::MitRanges;
use frictionless_drives::can::units::{CommandUnit, JointUnits};

use crate::error::{Checker, ConfigError};
use crate::schema::{
    BackendKind, BusConfig, BusJointConfig, BusLoad, CanProtocol, Cia402Config, Cia402Drive,
    Cia402DriveLoop, Cia402Mode, Cia402Object, Config, JointConfig, MAX_BUSES, RawConfig,
    ResolvedBus, ResolvedDrive,
};

/// One line per bus for `frictiond --check` (empty without buses).
pub fn bus_summary(cfg: &Config) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    for (b, bus) in cfg.buses.iter().enumerate() {
        let _ = writeln!(
            s,
            "  bus[{b}] {} ({:?}): {}",
            bus.interface, bus.protocol, bus.load
        );
        for d in &bus.joints {
            let _ = write!(
                s,
                "    joint[{}] {} node {} command {:?}",
                d.index, cfg.raw.joint[d.joint_pos].name, d.node_id, d.units.command
            );
            if let Some(x) = &d.cia402 {
                let sdo = |v: Option<String>| v.unwrap_or_else(|| "SDO read".into());
                let _ = write!(
                    s,
                    ", cia402 {:?} (0x6060 = {}), rated torque {} mNm, max torque {} ‰, {} bits per tick, fault reset {}",
                    x.cfg.mode,
                    x.op_mode,
                    sdo(x.cfg.rated_torque_mnm.map(|v| v.to_string())),
                    sdo(x.cfg.max_torque_permille.map(|v| v.to_string())),
                    x.bits_per_tick,
                    if x.cfg.fault_reset {
                        "allowed"
                    } else {
                        "not allowed"
                    }
                );
            }
            let _ = writeln!(s);
        }
    }
    s
}

/// Validates `[[bus]]` against `[backend] kind` and the joints; computes every bus's load. The steps:
/// the section count ([`check_bus_sections`]), per bus its own keys ([`check_bus`]), per drive its
/// resolution against `[[joint]]` ([`resolve_drive`]), the bus-load budget ([`bus_load`]) and finally
/// that every joint sits on exactly one bus.
pub(crate) fn resolve_buses(
    c: &Checker,
    raw: &RawConfig,
    rate_hz: f64,
) -> Result<Vec<ResolvedBus>, ConfigError> {
    if !check_bus_sections(c, raw)? {
        return Ok(Vec::new());
    }
    // Where each `[[joint]]` sits: (bus, position on the bus).
    let mut on_bus: Vec<Option<(usize, usize)>> = vec![None; raw.joint.len()];
    let mut out = Vec::with_capacity(raw.bus.len());
    for (b, bus) in raw.bus.iter().enumerate() {
        check_bus(c, b, bus)?;
        let mut drives = Vec::with_capacity(bus.joint.len());
        for k in 0..bus.joint.len() {
            drives.push(resolve_drive(c, raw, b, k, &mut on_bus)?);
        }
        let load = bus_load(c, b, bus, &drives, rate_hz)?;
        out.push(ResolvedBus {
            interface: bus.interface.clone(),
            protocol: bus.protocol,
            host_id: bus.host_id,
            feedback_timeout_ticks: bus.feedback_timeout_ticks,
            joints: drives,
            load,
        });
    }
    if let Some(pos) = on_bus.iter().position(Option::is_none) {
        return Err(c.fail(
            format!("joint[{pos}].name"),
            format!("{:?}", raw.joint[pos].name),
            "with [backend] kind = \"can\" every [[joint]] must be on exactly one [[bus]]",
        ));
    }
    Ok(out)
}

/// `[[bus]]` sections are required (1..=[`MAX_BUSES`]) with `[backend] kind = "can"` and forbidden
/// otherwise. Returns whether there are buses to resolve.
pub(crate) fn check_bus_sections(c: &Checker, raw: &RawConfig) -> Result<bool, ConfigError> {
    if raw.backend.kind != BackendKind::Can {
        if !raw.bus.is_empty() {
            return Err(c.fail(
                "bus".into(),
                format!("{} section(s)", raw.bus.len()),
                "[[bus]] is only valid with [backend] kind = \"can\"",
            ));
        }
        return Ok(false);
    }
    if raw.bus.is_empty() {
        return Err(c.fail(
            "bus".into(),
            "[]",
            "[backend] kind = \"can\" needs at least one [[bus]]",
        ));
    }
    if raw.bus.len() > MAX_BUSES {
        return Err(c.fail(
            "bus".into(),
            raw.bus.len(),
            &format!("at most {MAX_BUSES} buses"),
        ));
    }
    Ok(true)
}

/// The keys of `bus[b]` itself (interface, bitrate, load limit, timeout, host id).
pub(crate) fn check_bus(c: &Checker, b: usize, bus: &BusConfig) -> Result<(), ConfigError> {
    let key = |name: &str| format!("bus[{b}].{name}");
    check_interface(c, &key("interface"), &bus.interface)?;
    if bus.bitrate == 0 {
        return Err(c.fail(key("bitrate"), 0, "must be > 0 [bit/s]"));
    }
    if !(bus.max_load.is_finite() && bus.max_load > 0.0 && bus.max_load <= 1.0) {
        return Err(c.fail(key("max_load"), bus.max_load, "must be in (0, 1]"));
    }
    if bus.feedback_timeout_ticks == 0 {
        return Err(c.fail(key("feedback_timeout_ticks"), 0, "must be >= 1"));
    }
    if bus.joint.is_empty() {
        return Err(c.fail(key("joint"), "[]", "a bus needs at least one [[bus.joint]]"));
    }
    match bus.protocol {
        CanProtocol::Mit => {
            if bus.host_id > frictionless_drives::can::frame::SFF_MAX {
                return Err(c.fail(
                    key("host_id"),
                    bus.host_id,
                    "must be a standard id 0..=2047",
                ));
            }
        }
        CanProtocol::Odrive | CanProtocol::Cia402 => {
            if bus.host_id != 0 {
                return Err(c.fail(
                    key("host_id"),
                    bus.host_id,
                    "only used by protocol = \"mit\"",
                ));
            }
        }
    }
    Ok(())
}

/// Resolves `bus[b].joint[k]` against the `[[joint]]` table (recording it in `on_bus`): the joint it
/// names, its node id, its units and the protocol's ranges.
pub(crate) fn resolve_drive(
    c: &Checker,
    raw: &RawConfig,
    b: usize,
    k: usize,
    on_bus: &mut [Option<(usize, usize)>],
) -> Result<ResolvedDrive, ConfigError> {
    let bus = &raw.bus[b];
    let bj = &bus.joint[k];
    let key = |name: &str| format!("bus[{b}].joint[{k}].{name}");
    let Some(pos) = raw.joint.iter().position(|j| j.name == bj.joint) else {
        return Err(c.fail(
            key("joint"),
            format!("{:?}", bj.joint),
            "no [[joint]] has this name",
        ));
    };
    if let Some((ob, ok)) = on_bus[pos] {
        return Err(c.fail(
            key("joint"),
            format!("{:?}", bj.joint),
            &format!("joint is already on bus[{ob}].joint[{ok}] (each joint on exactly one bus)"),
        ));
    }
    on_bus[pos] = Some((b, k));
    if bus.joint[..k].iter().any(|o| o.node_id == bj.node_id) {
        return Err(c.fail(key("node_id"), bj.node_id, "duplicate node id on this bus"));
    }
    let j = &raw.joint[pos];
    if j.kp != 0.0 || j.ki != 0.0 {
        return Err(c.fail(
            format!("joint[{pos}].kp"),
            format!("kp = {}, ki = {}", j.kp, j.ki),
            "joints on a CAN bus have no joint-torque measurement: kp and ki must be 0",
        ));
    }
    let angle = bus.protocol.feedback_angle();
    let units = JointUnits::new(bj.command_unit, j.kt, j.gear_ratio, angle)
        .map_err(|e| c.fail(format!("joint[{pos}]"), &j.name, &e.to_string()))?;
    if bus.protocol != CanProtocol::Cia402 && bj.cia402.is_some() {
        return Err(c.fail(key("cia402"), "<set>", "only used by protocol = \"cia402\""));
    }
    let (mit, reply_units, cia402) = match bus.protocol {
        CanProtocol::Odrive => (None, odrive_drive(c, &key, bj, units)?, None),
        CanProtocol::Mit => {
            let (ranges, reply) = mit_drive(c, &key, b, bus, bj, j, units)?;
            (Some(ranges), reply, None)
        }
        CanProtocol::Cia402 => {
            let (reply, d) = cia402_drive(c, &key, bj, j, units)?;
            (None, reply, Some(d))
        }
    };
    Ok(ResolvedDrive {
        joint_pos: pos,
        index: j.index,
        node_id: bj.node_id,
        units,
        reply_units,
        mit,
        max_curr_a: j.max_curr,
        cia402,
    })
}

/// ODrive drive keys: node id 0..=63, no MIT keys. Returns the reply units (Iq is a current).
pub(crate) fn odrive_drive(
    c: &Checker,
    key: &dyn Fn(&str) -> String,
    bj: &BusJointConfig,
    units: JointUnits,
) -> Result<JointUnits, ConfigError> {
    if bj.node_id > u32::from(frictionless_drives::can::odrive::NODE_MAX) {
        return Err(c.fail(key("node_id"), bj.node_id, "ODrive node ids are 0..=63"));
    }
    refuse_mit_keys(c, key, bj)?;
    Ok(JointUnits {
        command: CommandUnit::Current,
        ..units
    })
}

/// The MIT-only keys of a drive on another protocol are refused, naming the first one set.
fn refuse_mit_keys(
    c: &Checker,
    key: &dyn Fn(&str) -> String,
    bj: &BusJointConfig,
) -> Result<(), ConfigError> {
    let mit_keys = [
        ("p_max", bj.p_max.is_some()),
        ("v_max", bj.v_max.is_some()),
        ("t_max", bj.t_max.is_some()),
        ("i_max", bj.i_max.is_some()),
        ("kp_max", bj.kp_max.is_some()),
        ("kd_max", bj.kd_max.is_some()),
        ("reply_unit", bj.reply_unit.is_some()),
    ];
    for (n, set) in mit_keys {
        if set {
            return Err(c.fail(key(n), "<set>", "only used by protocol = \"mit\""));
        }
    }
    Ok(())
}

/// CiA 402 drive keys: node id 1..=127, `command_unit = "motor_torque"` (targets are ‰ of the motor
/// rated torque), `[bus.joint.cia402]` with a velocity unit, mode and drive loop consistent, the
/// optional objects complete, the heartbeat times, and — when rated and max torque are given — a
/// max torque that covers the joint's current clamp. Returns the reply units (torque actual is a
/// motor torque) and the resolved drive with its PDO layout.
pub(crate) fn cia402_drive(
    c: &Checker,
    key: &dyn Fn(&str) -> String,
    bj: &BusJointConfig,
    j: &JointConfig,
    units: JointUnits,
) -> Result<(JointUnits, Cia402Drive), ConfigError> {
    if !(1..=127).contains(&bj.node_id) {
        return Err(c.fail(key("node_id"), bj.node_id, "CANopen node ids are 1..=127"));
    }
    refuse_mit_keys(c, key, bj)?;
    if bj.command_unit != CommandUnit::MotorTorque {
        return Err(c.fail(
            key("command_unit"),
            format!("{:?}", bj.command_unit),
            "CiA 402 torque targets are per mille of the motor rated torque: command_unit must be \"motor_torque\"",
        ));
    }
    let Some(cfg) = bj.cia402 else {
        return Err(c.fail(
            key("cia402"),
            "<missing>",
            "required by protocol = \"cia402\" ([bus.joint.cia402] with at least velocity_unit_rad_s)",
        ));
    };
    let k = |n: &str| key(&format!("cia402.{n}"));
    let op_mode = cia402_op_mode(c, &k, &cfg)?;
    cia402_scales(c, &k, &cfg)?;
    let enc = cfg
        .joint_encoder
        .as_ref()
        .map(|o| cia402_object(c, &k, "joint_encoder", o, true))
        .transpose()?;
    let temp = cfg
        .temperature
        .as_ref()
        .map(|o| cia402_object(c, &k, "temperature", o, false))
        .transpose()?;
    let hb_timeout = cia402_heartbeat(c, &k, &cfg)?;
    let layout = Layout::new(
        cfg.mode == Cia402Mode::TorqueOffset,
        enc,
        temp,
        cfg.temperature_every,
    )
    .map_err(|e| c.fail(key("cia402"), "<mapping>", &e.to_string()))?;
    cia402_max_torque(c, &k, &cfg, j, units)?;
    let bits_per_tick = layout.bits_per_tick();
    Ok((
        JointUnits {
            command: CommandUnit::MotorTorque,
            ..units
        },
        Cia402Drive {
            cfg,
            op_mode,
            heartbeat_timeout_ms: hb_timeout,
            layout,
            bits_per_tick,
        },
    ))
}

/// The operation mode of a `[bus.joint.cia402]` (CST, or the drive's own CSP/CSV loop under a
/// torque offset).
fn cia402_op_mode(
    c: &Checker,
    k: &dyn Fn(&str) -> String,
    cfg: &Cia402Config,
) -> Result<i8, ConfigError> {
    Ok(match (cfg.mode, cfg.drive_loop) {
        (Cia402Mode::Cst, None) => frictionless_drives::can::cia402::mode::CST,
        (Cia402Mode::Cst, Some(l)) => {
            return Err(c.fail(
                k("drive_loop"),
                format!("{l:?}"),
                "only used by mode = \"torque_offset\"",
            ));
        }
        (Cia402Mode::TorqueOffset, Some(Cia402DriveLoop::Csp)) => {
            frictionless_drives::can::cia402::mode::CSP
        }
        (Cia402Mode::TorqueOffset, Some(Cia402DriveLoop::Csv)) => {
            frictionless_drives::can::cia402::mode::CSV
        }
        (Cia402Mode::TorqueOffset, None) => {
            return Err(c.fail(
                k("drive_loop"),
                "<missing>",
                "mode = \"torque_offset\" needs the drive's own loop: \"csp\" or \"csv\"",
            ));
        }
    })
}

/// The scales a `[bus.joint.cia402]` states (rated and max torque, counts per revolution: each
/// positive where given, else read by SDO) and its velocity unit (required) [motor rad/s per unit].
fn cia402_scales(
    c: &Checker,
    k: &dyn Fn(&str) -> String,
    cfg: &Cia402Config,
) -> Result<(), ConfigError> {
    if cfg.rated_torque_mnm == Some(0) {
        return Err(c.fail(
            k("rated_torque_mnm"),
            0,
            "must be > 0 [mNm] (or left out: read 0x6076 by SDO)",
        ));
    }
    if cfg.max_torque_permille == Some(0) {
        return Err(c.fail(
            k("max_torque_permille"),
            0,
            "must be > 0 [‰ of rated] (or left out: read 0x6072 by SDO)",
        ));
    }
    if let Some(n) = cfg.counts_per_rev {
        c.finite_pos(k("counts_per_rev"), n)?;
    }
    let Some(vel) = cfg.velocity_unit_rad_s else {
        return Err(c.fail(
            k("velocity_unit_rad_s"),
            "<missing>",
            "required: motor rad/s per unit of 0x606C (vendor-specific; e.g. 0.10471975511965977 for rpm)",
        ));
    };
    c.finite_pos(k("velocity_unit_rad_s"), vel)?;
    Ok(())
}

/// One optional PDO object of a `[bus.joint.cia402]` (`joint_encoder` with its counts per joint
/// revolution, or `temperature` with its °C per unit) as a PDO entry.
fn cia402_object(
    c: &Checker,
    k: &dyn Fn(&str) -> String,
    name: &str,
    o: &Cia402Object,
    encoder: bool,
) -> Result<PdoEntry, ConfigError> {
    let kk = |f: &str| k(&format!("{name}.{f}"));
    if !matches!(o.bits, 8 | 16 | 32) {
        return Err(c.fail(kk("bits"), o.bits, "must be 8, 16 or 32"));
    }
    match (encoder, o.counts_per_rev, o.unit_c) {
        (true, Some(n), None) => c.finite_pos(kk("counts_per_rev"), n)?,
        (true, None, _) => {
            return Err(c.fail(
                kk("counts_per_rev"),
                "<missing>",
                "required: increments per joint revolution",
            ));
        }
        (true, Some(_), Some(_)) => {
            return Err(c.fail(kk("unit_c"), "<set>", "only used by the temperature object"));
        }
        (false, None, Some(u)) => {
            if !(u.is_finite() && u != 0.0) {
                return Err(c.fail(kk("unit_c"), u, "must be finite and non-zero [°C per unit]"));
            }
        }
        (false, None, None) => {
            return Err(c.fail(
                kk("unit_c"),
                "<missing>",
                "required: °C per unit (e.g. 0.001 for m°C)",
            ));
        }
        (false, Some(_), _) => {
            return Err(c.fail(
                kk("counts_per_rev"),
                "<set>",
                "only used by the joint encoder",
            ));
        }
    }
    Ok(PdoEntry::new(o.index, o.sub, o.bits))
}

/// The temperature object's SYNC divider and the heartbeat keys; returns the heartbeat consumer's
/// timeout [ms] (default three heartbeat periods).
fn cia402_heartbeat(
    c: &Checker,
    k: &dyn Fn(&str) -> String,
    cfg: &Cia402Config,
) -> Result<u32, ConfigError> {
    if !(1..=240).contains(&cfg.temperature_every) {
        return Err(c.fail(
            k("temperature_every"),
            cfg.temperature_every,
            "must be 1..=240 SYNCs",
        ));
    }
    if cfg.heartbeat_ms == 0 {
        return Err(c.fail(
            k("heartbeat_ms"),
            0,
            "must be 1..=65535 [ms] (the drive's heartbeat is how a silent node is found)",
        ));
    }
    let hb_timeout = cfg
        .heartbeat_timeout_ms
        .unwrap_or(3 * u32::from(cfg.heartbeat_ms));
    if hb_timeout <= u32::from(cfg.heartbeat_ms) {
        return Err(c.fail(
            k("heartbeat_timeout_ms"),
            hb_timeout,
            &format!("must be > heartbeat_ms = {}", cfg.heartbeat_ms),
        ));
    }
    Ok(hb_timeout)
}

/// With both rated and max torque stated: the joint's current clamp must fit the drive's max
/// torque (else the drive would clamp silently).
fn cia402_max_torque(
    c: &Checker,
    k: &dyn Fn(&str) -> String,
    cfg: &Cia402Config,
    j: &JointConfig,
    units: JointUnits,
) -> Result<(), ConfigError> {
    if let (Some(rated), Some(max)) = (cfg.rated_torque_mnm, cfg.max_torque_permille) {
        let max_nm = f64::from(rated) * f64::from(max.min(i16::MAX as u16)) / 1e6;
        let max_cmd = units.command_from_current(j.max_curr).abs();
        if max_cmd > max_nm * (1.0 + 1e-12) {
            return Err(c.fail(
                k("max_torque_permille"),
                max,
                &format!(
                    "joint {:?} max_curr = {} A is {max_cmd} Nm motor torque, more than the drive's max torque {max_nm} Nm (the drive would clamp silently)",
                    j.name, j.max_curr
                ),
            ));
        }
    }
    Ok(())
}

/// MIT drive keys: motor id 1..=255 (not the host id), the fixed-point ranges, and a feed-forward
/// range wide enough for the joint's current clamp. Returns the ranges and the reply units.
pub(crate) fn mit_drive(
    c: &Checker,
    key: &dyn Fn(&str) -> String,
    b: usize,
    bus: &BusConfig,
    bj: &BusJointConfig,
    j: &JointConfig,
    units: JointUnits,
) -> Result<(MitRanges, JointUnits), ConfigError> {
    if !(1..=255).contains(&bj.node_id) {
        return Err(c.fail(
            key("node_id"),
            bj.node_id,
            "MIT motor ids are 1..=255 (byte 0 of the reply)",
        ));
    }
    if bj.node_id == bus.host_id {
        return Err(c.fail(
            key("node_id"),
            bj.node_id,
            &format!("equals bus[{b}].host_id"),
        ));
    }
    let need = |n: &str, v: Option<f64>| -> Result<f64, ConfigError> {
        let v = v.ok_or_else(|| c.fail(key(n), "<missing>", "required by protocol = \"mit\""))?;
        c.finite_pos(key(n), v)?;
        Ok(v)
    };
    let p = need("p_max", bj.p_max)?;
    let v = need("v_max", bj.v_max)?;
    let t = need("t_max", bj.t_max)?;
    let i = need("i_max", bj.i_max)?;
    let kp = need("kp_max", bj.kp_max.or(Some(500.0)))?;
    let kd = need("kd_max", bj.kd_max.or(Some(5.0)))?;
    let ranges = MitRanges {
        p_min_rad: -p,
        p_max_rad: p,
        v_min_rad_s: -v,
        v_max_rad_s: v,
        kp_min_nm_rad: 0.0,
        kp_max_nm_rad: kp,
        kd_min_nm_s_rad: 0.0,
        kd_max_nm_s_rad: kd,
        t_min_nm: -t,
        t_max_nm: t,
        i_min_a: -i,
        i_max_a: i,
    };
    // The largest command the law can produce must be representable on the wire.
    let max_cmd = units.command_from_current(j.max_curr).abs();
    if max_cmd > t * (1.0 + 1e-12) {
        return Err(c.fail(
            key("t_max"),
            t,
            &format!(
                "joint {:?} max_curr = {} A is {max_cmd} in command_unit {:?}: t_max must cover it (the drive would clamp silently)",
                j.name, j.max_curr, bj.command_unit
            ),
        ));
    }
    let reply = JointUnits {
        command: bj.reply_unit.unwrap_or(CommandUnit::Current),
        ..units
    };
    Ok((ranges, reply))
}

/// The worst-case load of `bus[b]` with its `drives` at `rate_hz`; refused above `max_load`. CiA
/// 402: each drive's own layout plus one SYNC per tick.
pub(crate) fn bus_load(
    c: &Checker,
    b: usize,
    bus: &BusConfig,
    drives: &[ResolvedDrive],
    rate_hz: f64,
) -> Result<BusLoad, ConfigError> {
    // At most MAX_JOINTS drives (each joint on one bus).
    let n = drives.len() as u32;
    let per_drive = |d: &ResolvedDrive| {
        d.cia402.map_or(
            (
                bus.protocol.bits_per_joint_tick(),
                bus.protocol.frames_per_joint_tick(),
            ),
            |x| (x.bits_per_tick, x.layout.frames_per_tick()),
        )
    };
    let (mut total_bits, mut total_frames) = (0u64, 0u32);
    let (mut bits, mut frames) = (
        bus.protocol.bits_per_joint_tick(),
        bus.protocol.frames_per_joint_tick(),
    );
    for (k, d) in drives.iter().enumerate() {
        let (b_, f_) = per_drive(d);
        total_bits += u64::from(b_);
        total_frames += f_;
        if k == 0 || b_ > bits {
            (bits, frames) = (b_, f_);
        }
    }
    let bus_bits = bus.protocol.bits_per_bus_tick();
    total_bits += u64::from(bus_bits);
    total_frames += u32::from(bus_bits > 0);
    let load = BusLoad {
        n_joints: n,
        frames_per_s: f64::from(total_frames) * rate_hz,
        bits_per_joint_tick: bits,
        bits_per_bus_tick: bus_bits,
        frames_per_joint_tick: frames,
        bitrate_bps: bus.bitrate,
        load: busload::load_fraction_bits(total_bits, rate_hz, bus.bitrate as f64),
        limit: bus.max_load,
    };
    if !(load.load.is_finite() && load.load <= bus.max_load) {
        return Err(c.fail(
            format!("bus[{b}].max_load"),
            bus.max_load,
            &format!(
                "bus {} over its load limit at {rate_hz} Hz: {load}",
                bus.interface
            ),
        ));
    }
    Ok(load)
}

/// Linux `IFNAMSIZ`: interface names are at most 15 bytes plus the NUL.
pub(crate) const IFNAMSIZ: usize = 16;

/// An interface name the kernel accepts (1–15 bytes, no '/', NUL or whitespace) or `fd:N`.
pub(crate) fn check_interface(c: &Checker, key: &str, name: &str) -> Result<(), ConfigError> {
    if let Some(n) = name.strip_prefix("fd:") {
        return match n.parse::<i32>() {
            Ok(fd) if fd >= 3 => Ok(()),
            _ => Err(c.fail(
                key.into(),
                format!("{name:?}"),
                "fd:N needs an inherited descriptor N >= 3",
            )),
        };
    }
    let ok = !name.is_empty()
        && name.len() < IFNAMSIZ
        && !name
            .bytes()
            .any(|b| b == b'/' || b == 0 || b.is_ascii_whitespace());
    if ok {
        Ok(())
    } else {
        Err(c.fail(
            key.into(),
            format!("{name:?}"),
            "must be a network interface name (1-15 bytes) or fd:N",
        ))
    }
}

//! The CAN buses: `[[bus]]` checked against `[backend]` and the joints, each drive resolved
//! (node id, units, MIT ranges), the worst-case bus load, and the `--check` summary.

use frictionless_drives::can::busload;
use frictionless_drives::can::mit::MitRanges;
use frictionless_drives::can::units::{CommandUnit, JointUnits};

use crate::schema::{
    BackendKind, BusConfig, BusJointConfig, CanProtocol, Config, JointConfig, MAX_BUSES, RawConfig,
    ResolvedBus, ResolvedDrive,
};
use crate::validate::{Checker, ConfigError};

/// Worst-case bus load of one bus from the config.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusLoad {
    /// Drives on the bus.
    pub n_joints: u32,
    /// Frames per second on the bus (commands and feedback).
    pub frames_per_s: f64,
    /// Worst-case bits (with stuffing) of the frames one joint puts on the bus per tick.
    pub bits_per_joint_tick: u32,
    /// Frames per joint per tick.
    pub frames_per_joint_tick: u32,
    /// Bitrate [bit/s].
    pub bitrate_bps: u64,
    /// Load fraction (1 = saturated).
    pub load: f64,
    /// Configured limit fraction.
    pub limit: f64,
}

impl std::fmt::Display for BusLoad {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} joint(s): {:.0} frames/s, {} bits per joint and tick in {} frame(s) (worst-case stuffing), load {:.1} % of {} bit/s (limit {:.1} %)",
            self.n_joints,
            self.frames_per_s,
            self.bits_per_joint_tick,
            self.frames_per_joint_tick,
            100.0 * self.load,
            self.bitrate_bps,
            100.0 * self.limit
        )
    }
}

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
            let _ = writeln!(
                s,
                "    joint[{}] {} node {} command {:?}",
                d.index, cfg.raw.joint[d.joint_pos].name, d.node_id, d.units.command
            );
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
        let load = bus_load(c, b, bus, drives.len(), rate_hz)?;
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
        CanProtocol::Odrive => {
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
    let (mit, reply_units) = match bus.protocol {
        CanProtocol::Odrive => (None, odrive_drive(c, &key, bj, units)?),
        CanProtocol::Mit => {
            let (ranges, reply) = mit_drive(c, &key, b, bus, bj, j, units)?;
            (Some(ranges), reply)
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
    Ok(JointUnits {
        command: CommandUnit::Current,
        ..units
    })
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

/// The worst-case load of `bus[b]` with `n_drives` drives at `rate_hz`; refused above `max_load`.
pub(crate) fn bus_load(
    c: &Checker,
    b: usize,
    bus: &BusConfig,
    n_drives: usize,
    rate_hz: f64,
) -> Result<BusLoad, ConfigError> {
    let (bits, frames) = (
        bus.protocol.bits_per_joint_tick(),
        bus.protocol.frames_per_joint_tick(),
    );
    // At most MAX_JOINTS drives (each joint on one bus).
    let n = n_drives as u32;
    let load = BusLoad {
        n_joints: n,
        frames_per_s: f64::from(n * frames) * rate_hz,
        bits_per_joint_tick: bits,
        frames_per_joint_tick: frames,
        bitrate_bps: bus.bitrate,
        load: busload::load_fraction(n, bits, rate_hz, bus.bitrate as f64),
        limit: bus.max_load,
    };
    if busload::check_load(n, bits, rate_hz, bus.bitrate as f64, bus.max_load).is_err() {
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

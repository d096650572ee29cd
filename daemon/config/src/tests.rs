//! The config crate's unit tests.

use std::path::PathBuf;

use frictionless::features::{FeatureSpec, Signal};
use frictionless_drives::can::units::AngleUnit;

use super::*;
use crate::buses::*;
use crate::error::*;
use crate::models::*;
use crate::validate::*;

const GOOD: &str = r#"
[loop]
period_us = 1000
[backend]
kind = "shm"
service_prefix = "t"
[safety]
stale_after_ticks = 3
on_stale = "static_model"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
max_output_friction = 25.0
joint_velocity_threshold_rad_s = 0.01
lpf = { order = 2, cutoff_hz = 10.0 }
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55
[[joint]]
name = "ankle"
index = 3
gear_ratio = 160
kt = 0.0665
max_curr = 3.0
friction_model = "coulomb_viscous_stribeck"
kc = 1.0005
ka = 2.78
kv = 0.29
ks = 6.0
vs = 0.13
alpha = 0.6
"#;

fn p(text: &str) -> Result<Config, ConfigError> {
    parse(Path::new("/etc/x/test.toml"), text)
}

#[test]
fn good_config_parses_with_aliases_and_defaults() {
    let c = p(GOOD).unwrap();
    assert_eq!(c.raw.joint.len(), 2);
    assert_eq!(c.period_ns(), 1_000_000);
    assert_eq!(c.raw.safety.on_stale, OnStale::StaticModel);
    assert!(matches!(c.models[0], ModelSpec::Cv(p) if p.kc == 8.1));
    assert!(matches!(c.models[1], ModelSpec::Scv(p) if p.alpha == 0.6));
    // defaults
    assert_eq!(c.raw.joint[1].kfc, 1.0);
    assert_eq!(c.raw.joint[1].kp, 0.0);
    assert!(c.raw.joint[1].max_output_friction.is_infinite());
    assert_eq!(c.raw.loop_.cpu_dma_latency_us, None, "PM QoS is opt-in");
    let c = p(&GOOD.replace(
        "period_us = 1000",
        "period_us = 1000\ncpu_dma_latency_us = 0",
    ))
    .unwrap();
    assert_eq!(c.raw.loop_.cpu_dma_latency_us, Some(0));
}

#[test]
fn unknown_key_is_an_error_naming_it() {
    let e = p(&GOOD.replace("kfc = 0.85", "kfc = 0.85\nbwfilter_enabled = true"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bwfilter_enabled") && e.contains("test.toml"),
        "{e}"
    );
}

#[test]
fn bad_values_name_file_key_and_value() {
    let cases = [
        (
            "max_curr = 5.0",
            "max_curr = -5.0",
            "joint[0].max_curr",
            "-5",
        ),
        (
            "gear_ratio = 160",
            "gear_ratio = 0",
            "joint[1].gear_ratio",
            "0",
        ),
        ("index = 3", "index = 0", "joint[1].index", "0"),
        ("index = 3", "index = 64", "joint[1].index", "64"),
        (
            "cutoff_hz = 10.0",
            "cutoff_hz = 600.0",
            "joint[0].lpf.cutoff_hz",
            "600",
        ),
        ("vs = 0.13", "vs = 0.0", "joint[1].vs", "0"),
        ("kfc = 0.85", "kfc = 3.0", "joint[0].kfc", "3"),
        ("period_us = 1000", "period_us = 5", "loop.period_us", "5"),
        (
            "period_us = 1000",
            "period_us = 1000\ncpu_dma_latency_us = 3000000000",
            "loop.cpu_dma_latency_us",
            "3000000000",
        ),
        (
            "stale_after_ticks = 3",
            "stale_after_ticks = 0",
            "safety.stale_after_ticks",
            "0",
        ),
    ];
    for (from, to, key, val) in cases {
        let e = p(&GOOD.replace(from, to)).unwrap_err().to_string();
        assert!(
            e.contains("test.toml") && e.contains(key) && e.contains(val),
            "{from} → {to}: {e}"
        );
    }
}

#[test]
fn missing_and_misplaced_model_parameters_are_errors() {
    let e = p(&GOOD.replace("kv = 5.55\n", "")).unwrap_err().to_string();
    assert!(e.contains("joint[0].kv") && e.contains("missing"), "{e}");
    let e = p(&GOOD.replace("ka = 50.84", "ka = 50.84\nks = 1.0"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint[0].ks"), "{e}");
    let e = p(&GOOD.replace("friction_model = \"cv\"", "friction_model = \"bogus\""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("bogus"), "{e}");
}

#[test]
fn pinn_without_file_reports_resolved_path() {
    let text = GOOD.replace(
        "friction_model = \"cv\"\nkc = 8.1\nka = 50.84\nkv = 5.55",
        "friction_model = \"pinn\"\nmodel = \"models/knee.fwt\"",
    );
    let e = p(&text).unwrap_err().to_string();
    assert!(
        e.contains("joint[0].model") && e.contains("/etc/x/models/knee.fwt"),
        "{e}"
    );
}

const CAN: &str = r#"
[backend]
kind = "can"
[[joint]]
name = "knee"
index = 0
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"
[[joint]]
name = "ankle"
index = 1
gear_ratio = 160.0
kt = 0.0665
max_curr = 3.0
friction_model = "none"
[[bus]]
interface = "vcan0"
bitrate = 1000000
protocol = "mit"
[[bus.joint]]
joint = "knee"
node_id = 1
command_unit = "motor_torque"
p_max = 12.5
v_max = 65.0
t_max = 18.0
i_max = 40.0
[[bus]]
interface = "can1"
bitrate = 1000000
protocol = "odrive"
max_load = 0.5
joints = [{ joint = "ankle", node_id = 3, command_unit = "joint_torque" }]
"#;

#[test]
fn can_config_resolves_buses_units_and_load() {
    let c = p(CAN).unwrap();
    assert_eq!(c.buses.len(), 2);
    let mit = &c.buses[0];
    assert_eq!(
        (mit.protocol, mit.host_id, mit.feedback_timeout_ticks),
        (CanProtocol::Mit, 0, 5)
    );
    let d = mit.joints[0];
    assert_eq!(
        (d.index, d.node_id, d.units.command),
        (0, 1, CommandUnit::MotorTorque)
    );
    assert_eq!(d.mit.unwrap().t_min_nm, -18.0);
    assert_eq!(d.units.gear_ratio, -100.0);
    // 1 joint × 1 kHz × (135 + 115 worst-case bits: 8- and 6-byte frames) on 1 Mbit/s.
    assert!((mit.load.load - 0.25).abs() < 1e-12, "{}", mit.load.load);
    assert_eq!(mit.load.frames_per_s, 2000.0);
    let od = &c.buses[1];
    assert_eq!(od.joints[0].units.feedback_angle, AngleUnit::Rev);
    assert_eq!(od.joints[0].units.command, CommandUnit::JointTorque);
    assert_eq!(od.load.limit, 0.5);
    let s = bus_summary(&c);
    assert!(
        s.contains("bus[0] vcan0") && s.contains("25.0 %") && s.contains("bus[1] can1"),
        "{s}"
    );
}

#[test]
fn can_config_errors_name_key_and_value() {
    let cases = [
        ("node_id = 1", "node_id = 0", "bus[0].joint[0].node_id", "0"),
        (
            "node_id = 3",
            "node_id = 64",
            "bus[1].joint[0].node_id",
            "64",
        ),
        (
            "t_max = 18.0",
            "t_max = 0.5",
            "bus[0].joint[0].t_max",
            "0.5",
        ),
        ("i_max = 40.0\n", "", "bus[0].joint[0].i_max", "<missing>"),
        (
            "joint = \"ankle\"",
            "joint = \"knee\"",
            "bus[1].joint[0].joint",
            "knee",
        ),
        (
            "joint = \"ankle\"",
            "joint = \"elbow\"",
            "bus[1].joint[0].joint",
            "elbow",
        ),
        (
            "interface = \"can1\"",
            "interface = \"a/b\"",
            "bus[1].interface",
            "a/b",
        ),
        (
            "interface = \"can1\"",
            "interface = \"fd:x\"",
            "bus[1].interface",
            "fd:x",
        ),
        ("max_load = 0.5", "max_load = 1.5", "bus[1].max_load", "1.5"),
        (
            "bitrate = 1000000\nprotocol = \"odrive\"",
            "bitrate = 0\nprotocol = \"odrive\"",
            "bus[1].bitrate",
            "0",
        ),
        (
            "node_id = 3, command_unit",
            "node_id = 3, p_max = 1.0, command_unit",
            "bus[1].joint[0].p_max",
            "<set>",
        ),
        ("kind = \"can\"", "kind = \"shm\"", "bus", "2 section(s)"),
        (
            "max_curr = 5.0",
            "max_curr = 5.0\nkp = 0.5",
            "joint[0].kp",
            "kp = 0.5",
        ),
    ];
    for (from, to, key, val) in cases {
        assert!(CAN.contains(from), "{from}");
        let e = p(&CAN.replacen(from, to, 1)).unwrap_err().to_string();
        assert!(
            e.contains("test.toml") && e.contains(&format!("`{key}`")) && e.contains(val),
            "{from} → {to}: {e}"
        );
    }
    // Every joint on exactly one bus.
    let e = p(&CAN.replace(
        "joints = [{ joint = \"ankle\", node_id = 3, command_unit = \"joint_torque\" }]",
        "joints = []",
    ))
    .unwrap_err()
    .to_string();
    assert!(e.contains("bus[1].joint"), "{e}");
    let cut = CAN.find("[[bus]]\ninterface = \"can1\"").unwrap();
    let e = p(&CAN[..cut]).unwrap_err().to_string();
    assert!(
        e.contains("joint[1].name") && e.contains("exactly one"),
        "{e}"
    );
    let cut = CAN.find("[[bus]]").unwrap();
    let e = p(&CAN[..cut]).unwrap_err().to_string();
    assert!(
        e.contains("`bus`") && e.contains("at least one [[bus]]"),
        "{e}"
    );
}

fn mit_joints(n: usize, max_load: f64) -> String {
    let mut text = String::from("[backend]\nkind = \"can\"\n");
    for k in 0..n {
        text += &format!(
            "[[joint]]\nname = \"j{k}\"\nindex = {k}\ngear_ratio = 100.0\nkt = 0.1\nmax_curr = 5.0\nfriction_model = \"none\"\n"
        );
    }
    text += &format!(
        "[[bus]]\ninterface = \"can0\"\nbitrate = 1000000\nprotocol = \"mit\"\nmax_load = {max_load}\n"
    );
    for k in 0..n {
        text += &format!(
            "[[bus.joint]]\njoint = \"j{k}\"\nnode_id = {}\ncommand_unit = \"current\"\np_max = 12.5\nv_max = 65.0\nt_max = 5.0\ni_max = 40.0\n",
            k + 1
        );
    }
    text
}

#[test]
fn bus_over_its_load_limit_is_refused_with_the_numbers() {
    // Four MIT joints at 1 kHz on 1 Mbit/s: 4 × (135 + 115) bits = 100 % > 70 %.
    let e = p(&mit_joints(4, 0.7)).unwrap_err().to_string();
    for needle in [
        "bus[0].max_load",
        "8000 frames/s",
        "250 bits",
        "100.0 %",
        "limit 70.0 %",
        "1000000 bit/s",
    ] {
        assert!(e.contains(needle), "{needle}: {e}");
    }
    // Three fit a 75 % limit exactly; not a 74 % one.
    let c = p(&mit_joints(3, 0.75)).unwrap();
    assert!((c.buses[0].load.load - 0.75).abs() < 1e-12);
    let e = p(&mit_joints(3, 0.74)).unwrap_err().to_string();
    assert!(e.contains("75.0 %"), "{e}");
}

fn assert_refused(text: &str, key: &str, val: &str) {
    let e = p(text).unwrap_err().to_string();
    assert!(
        e.contains("test.toml") && e.contains(&format!("`{key}`")) && e.contains(val),
        "{key} = {val}: {e}"
    );
}

/// A CPU outside the online set (or beyond CPU_SETSIZE) is refused by `--check`.
#[test]
fn cpu_outside_the_online_set_is_refused() {
    let with_cpu = |cpu: usize| {
        GOOD.replace(
            "period_us = 1000",
            &format!("period_us = 1000\ncpu = {cpu}"),
        )
    };
    assert_refused(&with_cpu(1024), "loop.cpu", "1024");
    assert_refused(&with_cpu(usize::MAX), "loop.cpu", &usize::MAX.to_string());
    let online = online_cpus().expect("/sys/devices/system/cpu/online is readable here");
    let last = online.iter().map(|r| *r.end()).max().unwrap();
    p(&with_cpu(*online[0].start())).unwrap();
    if last + 1 < libc::CPU_SETSIZE as usize {
        assert_refused(&with_cpu(last + 1), "loop.cpu", &(last + 1).to_string());
    }
}

#[test]
fn rt_threads_helper_cpu_and_prefetch_are_checked() {
    let with =
        |extra: &str| GOOD.replace("period_us = 1000", &format!("period_us = 1000\n{extra}"));
    let c = p(&with("")).unwrap();
    assert_eq!(
        (
            c.raw.loop_.rt_threads,
            c.raw.loop_.helper_cpu,
            c.raw.loop_.prefetch
        ),
        (1, None, Prefetch::Off),
        "one RT thread, no prefetch by default"
    );
    let c = p(&with(
        "rt_threads = 2\nprefetch = \"lead\"\nprefetch_lead_us = 150",
    ))
    .unwrap();
    assert_eq!(
        (
            c.raw.loop_.rt_threads,
            c.raw.loop_.prefetch,
            c.raw.loop_.prefetch_lead_us
        ),
        (2, Prefetch::Lead, 150)
    );
    assert_eq!(
        p(&with("prefetch = \"after\"")).unwrap().raw.loop_.prefetch,
        Prefetch::After
    );
    for bad in [0, 3] {
        assert_refused(
            &with(&format!("rt_threads = {bad}")),
            "loop.rt_threads",
            &bad.to_string(),
        );
    }
    let e = p(&with("prefetch = \"sometimes\""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("prefetch") && e.contains("sometimes"), "{e}");
    assert_refused(
        &with("prefetch = \"lead\"\nprefetch_lead_us = 1000"),
        "loop.prefetch_lead_us",
        "1000",
    );
    assert_refused(
        &with("prefetch = \"lead\"\nprefetch_lead_us = 0"),
        "loop.prefetch_lead_us",
        "0",
    );
    // The lead is only checked when it is used.
    p(&with("prefetch_lead_us = 5000")).unwrap();
    let online = online_cpus().expect("/sys/devices/system/cpu/online is readable here");
    let first = *online[0].start();
    let last = online.iter().map(|r| *r.end()).max().unwrap();
    assert_refused(
        &with(&format!("helper_cpu = {first}")),
        "loop.helper_cpu",
        &first.to_string(),
    );
    p(&with(&format!("rt_threads = 2\nhelper_cpu = {first}"))).unwrap();
    assert_refused(
        &with(&format!(
            "rt_threads = 2\ncpu = {first}\nhelper_cpu = {first}"
        )),
        "loop.helper_cpu",
        &first.to_string(),
    );
    assert_refused(
        &with("rt_threads = 2\nhelper_cpu = 1024"),
        "loop.helper_cpu",
        "1024",
    );
    if last + 1 < libc::CPU_SETSIZE as usize {
        assert_refused(
            &with(&format!("rt_threads = 2\nhelper_cpu = {}", last + 1)),
            "loop.helper_cpu",
            &(last + 1).to_string(),
        );
    }
}

#[test]
fn cpu_lists_parse_as_the_kernel_writes_them() {
    assert_eq!(parse_cpu_list("0-3\n"), Some(vec![0..=3]));
    assert_eq!(parse_cpu_list("0,2-3,7"), Some(vec![0..=0, 2..=3, 7..=7]));
    assert_eq!(parse_cpu_list(""), None);
    assert_eq!(parse_cpu_list("x"), None);
    assert_eq!(parse_cpu_list("3-1"), None);
}

/// Values `--check` accepted but the start refused, or that switch a protection off.
#[test]
fn start_time_failures_and_unbounded_tick_counts_are_refused() {
    let long = "p".repeat(4000);
    assert_refused(
        &GOOD.replace(
            "service_prefix = \"t\"",
            &format!("service_prefix = \"{long}\""),
        ),
        "backend.service_prefix",
        "4000 bytes",
    );
    let max = "p".repeat(frictionless_shm_types::MAX_SERVICE_PREFIX_BYTES);
    p(&GOOD.replace(
        "service_prefix = \"t\"",
        &format!("service_prefix = \"{max}\""),
    ))
    .unwrap();
    assert_refused(
        &GOOD.replace("service_prefix = \"t\"", "service_prefix = \"iox2://x\""),
        "backend.service_prefix",
        "iox2://x",
    );
    let file = concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.toml");
    assert_refused(
        &GOOD.replace(
            "service_prefix = \"t\"",
            &format!("service_prefix = \"t\"\nroot_path = \"{file}\""),
        ),
        "backend.root_path",
        "Cargo.toml",
    );
    // A directory, or a path not created yet, is fine.
    let dir = env!("CARGO_MANIFEST_DIR");
    p(&GOOD.replace(
        "service_prefix = \"t\"",
        &format!("service_prefix = \"t\"\nroot_path = \"{dir}\""),
    ))
    .unwrap();
    p(&GOOD.replace(
        "service_prefix = \"t\"",
        "service_prefix = \"t\"\nroot_path = \"/nonexistent/iox\"",
    ))
    .unwrap();
    let u64max = u64::MAX.to_string();
    assert_refused(
        &GOOD.replace(
            "stale_after_ticks = 3",
            &format!("stale_after_ticks = {u64max}"),
        ),
        "safety.stale_after_ticks",
        &u64max,
    );
    assert_refused(
        &GOOD.replace(
            "period_us = 1000",
            &format!("period_us = 1000\nready_after_ticks = {u64max}"),
        ),
        "loop.ready_after_ticks",
        &u64max,
    );
    // 60 s at 1 kHz is the largest; at 10 kHz (period 100 µs) 600000 ticks.
    p(&GOOD.replace("stale_after_ticks = 3", "stale_after_ticks = 60000")).unwrap();
    assert_refused(
        &GOOD.replace("stale_after_ticks = 3", "stale_after_ticks = 60001"),
        "safety.stale_after_ticks",
        "60001",
    );
    p(&GOOD.replace(
        "period_us = 1000",
        "period_us = 100\nready_after_ticks = 600000",
    ))
    .unwrap();
}

fn shipped_model() -> String {
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/models/stress32_paper_f16_r-100.fwt"
    )
    .to_owned()
}

fn pinn_joint(name: &str, kt: f64, model: &str) -> String {
    format!(
        "[[joint]]\nname = \"{name}\"\nindex = {}\ngear_ratio = -100.0\nkt = {kt:?}\nmax_curr = 5.0\nfriction_model = \"pinn\"\nmodel = \"{model}\"\n",
        name.len()
    )
}

/// `ood = "static"` needs the joint's static model (CV, or SCV with all three Stribeck keys), a
/// PINN and a model that stores its training input range; the margin and the ramp are
/// range-checked; without `ood` a PINN joint flags only and still refuses static-model keys.
#[test]
fn out_of_range_settings_are_typed_and_checked() {
    let spec = FeatureSpec {
        set: frictionless::features::FeatureSet::DeltaThetaJointVel,
        history: 3,
        temperature: false,
    };
    let m = joint_model_with_range("knee", -100.0, 0.157, spec, true);
    // A model without a stored range (the shipped ones): the check never fires, so a static
    // fallback could never engage; refused naming the key, the value and why. `flag` (the
    // default) is accepted: it just never flags.
    let unranged = joint_model("knee", -100.0, 0.157, spec);
    let plain = format!(
        "[backend]\nkind = \"shm\"\n{}",
        pinn_joint("knee", 0.157, unranged.to_str().unwrap())
    );
    p(&plain).unwrap();
    p(&format!("{plain}ood = \"flag\"\n")).unwrap();
    let e = p(&format!(
        "{plain}ood = \"static\"\nkc = 1.0\nka = 20.0\nkv = 0.5\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("joint[0].ood")
            && e.contains("static")
            && e.contains("input range")
            && e.contains(unranged.to_str().unwrap()),
        "{e}"
    );
    let e = p(&format!(
        "[backend]\nkind = \"shm\"\n{}ood = \"static\"\nkc = 1.0\nka = 20.0\nkv = 0.5\n",
        pinn_joint("stress32_r-100", 0.156977705, &shipped_model())
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("joint[0].ood") && e.contains("input range"),
        "{e}"
    );
    let base = format!(
        "[backend]\nkind = \"shm\"\n{}",
        pinn_joint("knee", 0.157, m.to_str().unwrap())
    );
    let c = p(&base).unwrap();
    assert_eq!(c.raw.joint[0].ood, OodMode::Flag);
    assert_eq!(c.raw.joint[0].ood_margin, 0.1);
    assert_eq!(c.raw.joint[0].ood_ramp_ms, 20.0);
    assert!(matches!(
        c.models[0],
        ModelSpec::Pinn { fallback: None, .. }
    ));
    // No static model configured: refused at --check, naming the missing key.
    let e = p(&format!("{base}ood = \"static\"\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint[0].kc") && e.contains("ood"), "{e}");
    let cv = format!("{base}ood = \"static\"\nkc = 1.0\nka = 20.0\nkv = 0.5\n");
    let c = p(&cv).unwrap();
    assert!(matches!(
        c.models[0],
        ModelSpec::Pinn {
            fallback: Some(StaticFallback::Cv(cv)),
            ..
        } if cv.kc == 1.0
    ));
    let scv = format!("{cv}ks = 1.5\nvs = 0.1\nalpha = 1.0\n");
    assert!(matches!(
        p(&scv).unwrap().models[0],
        ModelSpec::Pinn {
            fallback: Some(StaticFallback::Scv(_)),
            ..
        }
    ));
    // Half an SCV is refused; static keys without `ood = "static"` too.
    let e = p(&format!("{cv}ks = 1.5\n")).unwrap_err().to_string();
    assert!(e.contains("joint[0].vs"), "{e}");
    let e = p(&format!("{base}kc = 1.0\n")).unwrap_err().to_string();
    assert!(e.contains("joint[0].kc"), "{e}");
    for (key, bad) in [
        ("ood_margin", "-0.1"),
        ("ood_margin", "nan"),
        ("ood_ramp_ms", "5000.0"),
    ] {
        let e = p(&format!("{cv}{key} = {bad}\n")).unwrap_err().to_string();
        assert!(e.contains(&format!("joint[0].{key}")), "{e}");
    }
    let e = p(&format!("{base}ood = \"sometimes\"\n"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("sometimes") || e.contains("unknown variant"),
        "{e}"
    );
    // A static-model joint cannot fall back to itself.
    let e = p(&GOOD.replacen("kv = 5.55", "kv = 5.55\nood = \"static\"", 1))
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint[0].ood"), "{e}");
}

/// A model recorded for another joint, or another k_t, is refused naming both values.
#[test]
fn model_for_another_joint_or_kt_is_refused() {
    let m = shipped_model();
    let head = "[backend]\nkind = \"shm\"\n";
    // The file records joint "stress32_r-100", gear ratio -100, k_t 0.156977705.
    p(&format!(
        "{head}{}",
        pinn_joint("stress32_r-100", 0.156977705, &m)
    ))
    .unwrap();
    let e = p(&format!("{head}{}", pinn_joint("l_knee", 0.156977705, &m)))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("joint[0].model")
            && e.contains("\"stress32_r-100\"")
            && e.contains("\"l_knee\""),
        "{e}"
    );
    let e = p(&format!("{head}{}", pinn_joint("stress32_r-100", 0.18, &m)))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("joint[0].model") && e.contains("0.156977705") && e.contains("0.18"),
        "{e}"
    );
    // Sharing a file does not lift the check: a joint that runs another joint's network must say
    // so with model_for (a template, as in config/stress32.toml).
    let other = format!(
        "{head}{}{}",
        pinn_joint("stress32_r-100", 0.156977705, &m),
        pinn_joint("bb", 0.066468037, &m)
    );
    let e = p(&other).unwrap_err().to_string();
    assert!(
        e.contains("joint[1].model") && e.contains("model_for"),
        "{e}"
    );
    let template = other.replacen(
        "name = \"bb\"",
        "name = \"bb\"\nmodel_for = \"stress32_r-100\"",
        1,
    );
    p(&template).unwrap();
    // model_for must name what the file records, and the gear ratio is still compared.
    let e = p(&template.replacen("model_for = \"stress32_r-100\"", "model_for = \"x\"", 1))
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint[1].model") && e.contains("\"x\""), "{e}");
    let e = p(&template.replacen("gear_ratio = -100.0", "gear_ratio = 100.0", 1))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("joint[0].model") && e.contains("gear_ratio"),
        "{e}"
    );
}

/// A random `.fwt` for joint `name` (gear ratio `r`, k_t `kt`) with the given inputs, in a
/// scratch dir.
fn joint_model(name: &str, r: f64, kt: f64, spec: FeatureSpec) -> PathBuf {
    joint_model_with_range(name, r, kt, spec, false)
}

/// A random model for `name`; with `range`, it stores a training input range.
fn joint_model_with_range(name: &str, r: f64, kt: f64, spec: FeatureSpec, range: bool) -> PathBuf {
    use frictionless::random::{RandomMlpSpec, seeded_mlp};
    use frictionless::weights::{InputRange, ModelFile, ModelMeta, TrainingMeta};
    let dir = std::env::temp_dir().join(format!("frictiond_config_inputs_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!(
        "{name}_{}_{}{}.fwt",
        spec.set,
        spec.temperature,
        if range { "_ranged" } else { "" }
    ));
    let mut training = TrainingMeta::unknown("config test", 0);
    if range {
        let mut blocks = [[0.0; 2]; frictionless::weights::layout::RANGE_BLOCKS];
        for b in blocks.iter_mut().take(spec.set.n_blocks()) {
            *b = [-1.0, 1.0];
        }
        training.input_range = Some(InputRange {
            blocks,
            temperature: if spec.temperature {
                [20.0, 40.0]
            } else {
                [0.0, 0.0]
            },
        });
    }
    let file = ModelFile {
        meta: ModelMeta {
            joint_name: name.into(),
            gear_ratio: frictionless::units::GearRatio::new(r).unwrap(),
            kt_nm_per_a: kt,
            features: spec,
            scv: None,
            training,
        },
        dtype: frictionless::mlp::StorageDtype::F32,
        mlp: seeded_mlp(&RandomMlpSpec::new(&[spec.n_inputs(), 4, 1]), 1).unwrap(),
    };
    frictionless::weights::write_file(&path, &file).unwrap();
    path
}

/// A PINN whose inputs the backend cannot supply is refused at load (`--check`,
/// reload) naming joint, set and field: both CAN protocols report motor-side values only (joint
/// values derived, so Δθ carries nothing) and no temperature; shm takes what the publisher writes.
#[test]
fn models_whose_inputs_the_backend_cannot_supply_are_refused() {
    use frictionless::features::FeatureSet;
    // CAN: knee (joint 0) on the MIT bus, ankle (joint 1) on the ODrive bus.
    let can_pinn = |model: &Path, k: usize| {
        let none = "friction_model = \"none\"";
        let pinn = format!("friction_model = \"pinn\"\nmodel = \"{}\"", model.display());
        let mut parts: Vec<&str> = CAN.split(none).collect();
        let tail = parts.split_off(k + 1);
        format!("{}{pinn}{}", parts.join(none), tail.join(none))
    };
    for set in FeatureSet::ALL {
        for temperature in [false, true] {
            let spec = FeatureSpec {
                set,
                history: 3,
                temperature,
            };
            let m = joint_model("knee", -100.0, 0.157, spec);
            let ankle = joint_model("ankle", 160.0, 0.0665, spec);
            let shm = format!(
                "[backend]\nkind = \"shm\"\n{}",
                pinn_joint("knee", 0.157, m.to_str().unwrap())
            );
            p(&shm).unwrap_or_else(|e| panic!("shm runs {spec}: {e}"));
            for (k, model, name, protocol) in
                [(0, &m, "knee", "mit"), (1, &ankle, "ankle", "odrive")]
            {
                let r = p(&can_pinn(model, k));
                let why = format!("{spec} on {protocol}");
                if set.uses_delta_theta() || temperature {
                    let e = r.expect_err(&why).to_string();
                    // A missing field is reported before the derived joint position.
                    let field = if temperature {
                        "`temperature_c`"
                    } else {
                        "`s_rad`"
                    };
                    assert!(
                        e.contains(&format!("joint[{k}].model"))
                            && e.contains(&format!("joint {name}"))
                            && e.contains(&format!("`{set}`"))
                            && e.contains(field)
                            && e.contains(protocol),
                        "{why}: {e}"
                    );
                } else {
                    r.unwrap_or_else(|e| panic!("{why}: {e}"));
                }
            }
        }
    }
    assert_eq!(
        signal_supply(
            BackendKind::Can,
            Some(CanProtocol::Odrive),
            Signal::JointVelRadS
        ),
        SignalSupply::DerivedFrom(Signal::MotorVelRadS)
    );
    assert_eq!(
        signal_supply(
            BackendKind::Can,
            Some(CanProtocol::Mit),
            Signal::MotorPosRad
        ),
        SignalSupply::Measured
    );
    assert_eq!(
        signal_supply(BackendKind::Shm, None, Signal::TemperatureC),
        SignalSupply::Publisher
    );
}

/// `n` joints on one CiA 402 bus; `extra` is appended to every `[bus.joint.cia402]`.
fn cia402_joints(n: usize, max_load: f64, extra: &str) -> String {
    let mut text = String::from("[backend]\nkind = \"can\"\n");
    for k in 0..n {
        text += &format!(
            "[[joint]]\nname = \"j{k}\"\nindex = {k}\ngear_ratio = 100.0\nkt = 0.1\nmax_curr = 5.0\nfriction_model = \"none\"\n"
        );
    }
    text += &format!(
        "[[bus]]\ninterface = \"can0\"\nbitrate = 1000000\nprotocol = \"cia402\"\nmax_load = {max_load}\n"
    );
    for k in 0..n {
        text += &format!(
            "[[bus.joint]]\njoint = \"j{k}\"\nnode_id = {}\ncommand_unit = \"motor_torque\"\n[bus.joint.cia402]\nvelocity_unit_rad_s = 0.1\n{extra}\n",
            k + 1
        );
    }
    text
}

#[test]
fn cia402_example_resolves_layout_scales_and_load() {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/can_cia402.toml"),
    )
    .unwrap();
    let c = p(&text).unwrap();
    let bus = &c.buses[0];
    assert_eq!(bus.protocol, CanProtocol::Cia402);
    let knee = bus.joints[0].cia402.unwrap();
    assert_eq!(knee.op_mode, 10);
    assert_eq!(knee.cfg.rated_torque_mnm, Some(500));
    assert_eq!(knee.heartbeat_timeout_ms, 300);
    assert_eq!(knee.layout.tpdo2.bytes(), 8, "velocity + joint encoder");
    assert_eq!(knee.bits_per_tick, 95 + 135 + 135);
    let ankle = bus.joints[1].cia402.unwrap();
    assert_eq!(
        (ankle.cfg.rated_torque_mnm, ankle.cfg.counts_per_rev),
        (None, None)
    );
    assert_eq!(ankle.bits_per_tick, 95 + 135 + 95);
    // SYNC 55 + 365 + 325 bits per ms on 1 Mbit/s.
    assert!((bus.load.load - 0.745).abs() < 1e-12, "{}", bus.load);
    assert_eq!(bus.load.bits_per_bus_tick, 55);
    let summary = bus_summary(&c);
    assert!(
        summary.contains("Cia402") && summary.contains("SDO read"),
        "{summary}"
    );
    assert!(summary.contains("+ 55 bits of SYNC"), "{summary}");
    // The knee maps a joint-side encoder: s_rad is measured (Δθ models are possible); the ankle's
    // is derived from the motor encoder; neither maps a temperature.
    assert_eq!(
        cia402_signal_supply(&knee, Signal::JointPosRad),
        SignalSupply::Measured
    );
    assert_eq!(
        cia402_signal_supply(&ankle, Signal::JointPosRad),
        SignalSupply::DerivedFrom(Signal::MotorPosRad)
    );
    assert_eq!(
        cia402_signal_supply(&ankle, Signal::TemperatureC),
        SignalSupply::Absent
    );
}

#[test]
fn cia402_bus_budget_counts_the_sync_and_refuses_a_third_node_at_1khz() {
    // Default layout without joint encoder: 95 + 135 + 95 = 325 bits per node, + 55 SYNC.
    let c = p(&cia402_joints(2, 0.75, "")).unwrap();
    assert!((c.buses[0].load.load - 0.705).abs() < 1e-12);
    let e = p(&cia402_joints(3, 0.75, "")).unwrap_err().to_string();
    for needle in [
        "bus[0].max_load",
        "103.0 %",
        "limit 75.0 %",
        "55 bits of SYNC",
    ] {
        assert!(e.contains(needle), "{needle}: {e}");
    }
    // At 500 Hz three fit (51.5 %).
    let slow = format!("[loop]\nperiod_us = 2000\n{}", cia402_joints(3, 0.75, ""));
    assert!((p(&slow).unwrap().buses[0].load.load - 0.515).abs() < 1e-12);
}

#[test]
fn cia402_config_errors_name_key_and_value() {
    let one = cia402_joints(1, 0.9, "");
    let sub = |from: &str, to: &str| {
        assert!(one.contains(from), "{from}");
        one.replacen(from, to, 1)
    };
    assert_refused(
        &sub("node_id = 1", "node_id = 128"),
        "bus[0].joint[0].node_id",
        "128",
    );
    assert_refused(
        &sub(
            "command_unit = \"motor_torque\"",
            "command_unit = \"current\"",
        ),
        "bus[0].joint[0].command_unit",
        "motor_torque",
    );
    assert_refused(
        &sub("velocity_unit_rad_s = 0.1", ""),
        "bus[0].joint[0].cia402.velocity_unit_rad_s",
        "<missing>",
    );
    assert_refused(
        &sub("[bus.joint.cia402]\nvelocity_unit_rad_s = 0.1", ""),
        "bus[0].joint[0].cia402",
        "<missing>",
    );
    assert_refused(
        &cia402_joints(1, 0.9, "mode = \"torque_offset\""),
        "bus[0].joint[0].cia402.drive_loop",
        "csp",
    );
    assert_refused(
        &cia402_joints(1, 0.9, "drive_loop = \"csv\""),
        "bus[0].joint[0].cia402.drive_loop",
        "Csv",
    );
    assert_refused(
        &cia402_joints(1, 0.9, "joint_encoder = { index = 0x60E4, sub = 1 }"),
        "bus[0].joint[0].cia402.joint_encoder.counts_per_rev",
        "<missing>",
    );
    assert_refused(
        &cia402_joints(
            1,
            0.9,
            "temperature = { index = 0x2031, sub = 1, bits = 12, unit_c = 0.001 }",
        ),
        "bus[0].joint[0].cia402.temperature.bits",
        "12",
    );
    assert_refused(
        &cia402_joints(1, 0.9, "heartbeat_ms = 100\nheartbeat_timeout_ms = 100"),
        "bus[0].joint[0].cia402.heartbeat_timeout_ms",
        "100",
    );
    assert_refused(
        &cia402_joints(1, 0.9, "rated_torque_mnm = 0"),
        "bus[0].joint[0].cia402.rated_torque_mnm",
        "0",
    );
    // kt·max_curr = 0.5 Nm > 400 mNm · 1000 ‰.
    assert_refused(
        &cia402_joints(1, 0.9, "rated_torque_mnm = 400\nmax_torque_permille = 1000"),
        "bus[0].joint[0].cia402.max_torque_permille",
        "1000",
    );
    p(&cia402_joints(
        1,
        0.9,
        "rated_torque_mnm = 500\nmax_torque_permille = 1000",
    ))
    .unwrap();
    // torque_offset with a drive loop resolves to CSP / CSV and maps 0x60B2.
    let c = p(&cia402_joints(
        1,
        0.9,
        "mode = \"torque_offset\"\ndrive_loop = \"csv\"",
    ))
    .unwrap();
    let d = c.buses[0].joints[0].cia402.unwrap();
    assert_eq!(d.op_mode, 9);
    assert_eq!(d.layout.rpdo1.entries()[1].index, 0x60B2);
    // The section on another protocol, and MIT keys on a CiA 402 drive, are refused.
    let mit = mit_joints(1, 0.9).replace(
        "i_max = 40.0\n",
        "i_max = 40.0\n[bus.joint.cia402]\nvelocity_unit_rad_s = 0.1\n",
    );
    assert_refused(&mit, "bus[0].joint[0].cia402", "<set>");
    assert_refused(
        &sub(
            "command_unit = \"motor_torque\"",
            "command_unit = \"motor_torque\"\nt_max = 1.0",
        ),
        "bus[0].joint[0].t_max",
        "<set>",
    );
    assert_refused(
        &sub("max_load = 0.9", "max_load = 0.9\nhost_id = 5"),
        "bus[0].host_id",
        "5",
    );
}

/// `[joint.speed_current_limit]`: parsed, defaulted, built into the law, and each rule refused
/// with its key and value.
#[test]
fn speed_current_limit_is_parsed_built_and_checked() {
    let with = |body: &str| {
        GOOD.replace(
            "lpf = { order = 2, cutoff_hz = 10.0 }",
            &format!("lpf = {{ order = 2, cutoff_hz = 10.0 }}\nspeed_current_limit = {{ {body} }}"),
        )
    };
    let c = p(&with(
        "rated_motor_speed_rad_s = 300.0, no_load_motor_speed_rad_s = 600.0",
    ))
    .unwrap();
    let l = c.raw.joint[0].speed_current_limit.unwrap();
    assert_eq!(l.safety_factor, 1.0, "default");
    assert!(c.raw.joint[1].speed_current_limit.is_none());
    let params = crate::params::build(&c, 0).unwrap();
    let g = params.joints[0].law.gains;
    // r = −100: 4.5 rad/s at the joint is 450 rad/s at the motor, half-way down the slope.
    assert!((g.current_limit_a(4.5) - 2.5).abs() < 1e-12);
    assert_eq!(g.current_limit_a(1.0), 5.0);
    assert_eq!(params.joints[1].law.gains.current_limit_a(100.0), 3.0);
    // Written back (frictl writes configs through these types) and read again, unchanged.
    let text = toml::to_string(&c.raw).unwrap();
    assert!(text.contains("speed_current_limit"), "{text}");
    for (body, key, val) in [
        (
            "rated_motor_speed_rad_s = 0.0, no_load_motor_speed_rad_s = 600.0",
            "joint[0].speed_current_limit.rated_motor_speed_rad_s",
            "0",
        ),
        (
            "rated_motor_speed_rad_s = 300.0, no_load_motor_speed_rad_s = 200.0",
            "joint[0].speed_current_limit.no_load_motor_speed_rad_s",
            "200",
        ),
        (
            "rated_motor_speed_rad_s = 300.0, no_load_motor_speed_rad_s = 600.0, safety_factor = 1.5",
            "joint[0].speed_current_limit.safety_factor",
            "1.5",
        ),
        (
            "rated_motor_speed_rad_s = 300.0, no_load_motor_speed_rad_s = 600.0, safety_factor = 0.0",
            "joint[0].speed_current_limit.safety_factor",
            "0",
        ),
    ] {
        assert_refused(&with(body), key, val);
    }
    let e = p(&with("rated_motor_speed_rad_s = 300.0"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("no_load_motor_speed_rad_s"), "{e}");
}

/// A runtime request is checked by the file's rules and names joint, key, value and rule.
#[test]
fn runtime_requests_follow_the_file_rules() {
    use crate::runtime::{Change, check};
    let c = p(GOOD).unwrap();
    let ok = |joint: &str, key: &str, value: &str| check(&c, 7, joint, key, value).unwrap();
    let set = ok("ankle", "kfc", "0.5");
    assert_eq!((set.generation, set.joint_index), (7, 3));
    assert_eq!(set.change, Change::Kfc(0.5));
    assert_eq!(
        ok("knee", "max_output_friction", "inf").change,
        Change::MaxOutputFriction(f64::INFINITY)
    );
    assert_eq!(ok("knee", "max_curr", "2.5").change, Change::MaxCurr(2.5));
    assert_eq!(
        ok("knee", "compensation", "off").change,
        Change::Compensation(false)
    );
    assert_eq!(
        ok("knee", "compensation", "on").change,
        Change::Compensation(true)
    );
    assert_eq!(ok("knee", "ood", "off").change, Change::Ood(OodMode::Off));
    for (joint, key, value, rule) in [
        ("knee", "kfc", "3", "must be in [0, 2]"),
        ("knee", "kfc", "-0.1", "must be in [0, 2]"),
        ("knee", "kfc", "x", "must be a number"),
        ("knee", "max_output_friction", "0", "must be > 0"),
        ("knee", "max_curr", "0", "must be finite and > 0"),
        (
            "knee",
            "max_curr",
            "6",
            "must be <= the file's max_curr (5)",
        ),
        ("knee", "compensation", "maybe", "must be on or off"),
        (
            "knee",
            "ood",
            "static",
            "only a PINN joint whose file sets ood",
        ),
        ("knee", "kp", "1", "not a runtime key"),
        ("hip", "kfc", "1", "no such joint (configured: knee, ankle)"),
    ] {
        let e = check(&c, 0, joint, key, value).unwrap_err();
        assert!(e.rule.starts_with(rule), "{key} = {value}: {e}");
        let text = e.to_string();
        assert!(
            text.contains(joint) && text.contains(key) && text.contains(value),
            "{text}"
        );
    }
    // The file's own refusals use the same words.
    assert_refused(
        &GOOD.replace("kfc = 0.85", "kfc = 3.0"),
        "joint[0].kfc",
        "must be in [0, 2]",
    );
}

/// `motor_encoder` is `absolute` by default and not written then; `incremental` refuses a fixed
/// Δθ offset (a zero that moves at every power-up), naming the key, the value and what to do, and
/// is written back by the serializer.
#[test]
fn an_incremental_motor_encoder_refuses_a_fixed_delta_theta_offset() {
    let c = p(GOOD).unwrap();
    assert_eq!(c.raw.joint[0].motor_encoder, MotorEncoder::Absolute);
    let written = toml::to_string(&c.raw).unwrap();
    assert!(!written.contains("motor_encoder"), "{written}");
    let with = |extra: &str| GOOD.replacen("kv = 5.55", &format!("kv = 5.55\n{extra}"), 1);
    p(&with(
        "motor_encoder = \"absolute\"\ndelta_theta_offset_motor_rad = 0.25",
    ))
    .unwrap();
    let c = p(&with("motor_encoder = \"incremental\"")).unwrap();
    assert_eq!(c.raw.joint[0].motor_encoder, MotorEncoder::Incremental);
    let again = toml::to_string(&c.raw).unwrap();
    assert!(again.contains("motor_encoder = \"incremental\""), "{again}");
    assert_eq!(p(&again).unwrap().raw, c.raw);
    let e = p(&with(
        "motor_encoder = \"incremental\"\ndelta_theta_offset_motor_rad = 0.25",
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("joint[0].delta_theta_offset_motor_rad")
            && e.contains("0.25")
            && e.contains("incremental")
            && e.contains("--motor-encoder incremental"),
        "{e}"
    );
    let e = p(&with("motor_encoder = \"relative\""))
        .unwrap_err()
        .to_string();
    assert!(e.contains("motor_encoder") && e.contains("relative"), "{e}");
}

/// [`GOOD`] with `alternates` after the knee's own model keys.
fn with_knee_alternates(alternates: &str) -> String {
    GOOD.replacen("kv = 5.55\n", &format!("kv = 5.55\n{alternates}"), 1)
}

#[test]
fn alternates_resolve_by_the_joints_rules_and_refusals_name_their_key() {
    let c = p(&with_knee_alternates(
        "[[joint.alternate]]\nname = \"scv_b\"\nfriction_model = \"scv\"\nkc = 1.0\nka = 40.0\nkv = 3.0\nks = 2.0\nvs = 0.1\nalpha = 0.8\n\
         [[joint.alternate]]\nname = \"off.1\"\nfriction_model = \"none\"\n",
    ))
    .unwrap();
    let names: Vec<&str> = c.alternates[0].iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["scv_b", "off.1"]);
    assert!(matches!(c.alternates[0][0].spec, ModelSpec::Scv(p) if p.ks == 2.0));
    assert_eq!(c.alternates[0][1].spec, ModelSpec::None);
    assert!(c.alternates[1].is_empty());
    assert_eq!(
        runtime::model_names(&c, 0),
        ["default", "scv_b", "off.1", "none"]
    );
    assert_eq!(runtime::model_kind(&c, 0, 1), ModelKind::Scv);
    assert_eq!(runtime::model_kind(&c, 0, 3), ModelKind::None);
    // Written back and re-read unchanged; the RT parameters hold every alternate.
    let back = p(&toml::to_string(&c.raw).unwrap()).unwrap();
    assert_eq!(back.raw, c.raw);
    let params = params::build(&c, 0).unwrap();
    assert_eq!(params.joints[0].slots.len(), 4);
    assert_eq!(params.joints[1].slots.len(), 2);

    for (alternates, key, value, rule) in [
        (
            "[[joint.alternate]]\nname = \"none\"\nfriction_model = \"none\"\n",
            "joint[0].alternate[0].name",
            "\"none\"",
            "reserved",
        ),
        (
            "[[joint.alternate]]\nname = \"a b\"\nfriction_model = \"none\"\n",
            "joint[0].alternate[0].name",
            "\"a b\"",
            "A-Z a-z 0-9",
        ),
        (
            "[[joint.alternate]]\nname = \"x\"\nfriction_model = \"none\"\n\
             [[joint.alternate]]\nname = \"x\"\nfriction_model = \"none\"\n",
            "joint[0].alternate[1].name",
            "\"x\"",
            "unique",
        ),
        (
            "[[joint.alternate]]\nname = \"cv2\"\nfriction_model = \"cv\"\nkc = 1.0\nka = 5.0\n",
            "joint[0].alternate[0].kv",
            "<missing>",
            "required by friction_model",
        ),
        (
            "[[joint.alternate]]\nname = \"cv2\"\nfriction_model = \"cv\"\nkc = -1.0\nka = 5.0\nkv = 1.0\n",
            "joint[0].alternate[0].kc",
            "-1",
            "",
        ),
    ] {
        let err = p(&with_knee_alternates(alternates)).unwrap_err();
        match &err {
            ConfigError::Invalid {
                key: k,
                value: v,
                requirement,
                ..
            } => {
                assert_eq!((k.as_str(), v.as_str()), (key, value), "{err}");
                assert!(requirement.contains(rule), "{err}");
            }
            other => panic!("{other}"),
        }
    }
    // An alternate's PINN file is read at load: a missing one names the alternate's key.
    let err = p(&with_knee_alternates(
        "[[joint.alternate]]\nname = \"net\"\nfriction_model = \"pinn\"\nmodel = \"missing.fwt\"\n",
    ))
    .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("joint[0].alternate[0].model") && msg.contains("/etc/x/missing.fwt"),
        "{msg}"
    );
    // An unknown key inside an alternate is refused by the schema.
    let err = p(&with_knee_alternates(
        "[[joint.alternate]]\nname = \"x\"\nfriction_model = \"none\"\nkp = 1.0\n",
    ))
    .unwrap_err();
    assert!(err.to_string().contains("kp"), "{err}");
}

#[test]
fn runtime_model_sets_name_the_available_models() {
    let c = p(&with_knee_alternates(
        "[[joint.alternate]]\nname = \"cv_b\"\nfriction_model = \"cv\"\nkc = 1.0\nka = 5.0\nkv = 1.0\n",
    ))
    .unwrap();
    let set = runtime::check(&c, 4, "knee", "model", "cv_b").unwrap();
    assert_eq!((set.generation, set.change), (4, runtime::Change::Model(1)));
    assert_eq!(
        runtime::check(&c, 4, "knee", "model", "none")
            .unwrap()
            .change,
        runtime::Change::Model(2)
    );
    let r = runtime::check(&c, 4, "knee", "model", "lugre").unwrap_err();
    assert_eq!(
        r.rule,
        "no such model of this joint (available: default, cv_b, none)"
    );
    let r = runtime::check(&c, 4, "ankle", "model", "cv_b").unwrap_err();
    assert!(r.rule.contains("(available: default, none)"), "{r}");
}

/// `make_paths_absolute` rewrites every relative path of the file — the joint's model, its
/// alternates' models, the iceoryx2 root — against the base, and leaves absolute ones.
#[test]
fn make_paths_absolute_covers_models_alternates_and_the_root() {
    let text = "[backend]\nkind = \"shm\"\nroot_path = \"ipc\"\n\
        [[joint]]\nname = \"a\"\nindex = 0\ngear_ratio = 1.0\nkt = 0.1\nmax_curr = 1.0\n\
        friction_model = \"pinn\"\nmodel = \"m/a.fwt\"\n\
        [[joint.alternate]]\nname = \"b\"\nfriction_model = \"pinn\"\nmodel = \"b.fwt\"\n\
        [[joint.alternate]]\nname = \"c\"\nfriction_model = \"pinn\"\nmodel = \"/abs/c.fwt\"\n";
    let mut raw: RawConfig = toml::from_str(text).unwrap();
    raw.make_paths_absolute(std::path::Path::new("/robot/cfg"));
    assert_eq!(raw.backend.root_path, Some(PathBuf::from("/robot/cfg/ipc")));
    let j = &raw.joint[0];
    assert_eq!(j.model, Some(PathBuf::from("/robot/cfg/m/a.fwt")));
    assert_eq!(
        j.alternate[0].model,
        Some(PathBuf::from("/robot/cfg/b.fwt"))
    );
    assert_eq!(j.alternate[1].model, Some(PathBuf::from("/abs/c.fwt")));
}

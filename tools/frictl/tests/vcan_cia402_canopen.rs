//! python-canopen's `RemoteNode` + `BaseNode402` profile as the master of the project's emulated
//! CiA 402 drive (`frictl sim serve --backend can --protocol cia402`) on a real kernel vcan0
//! (`tests/canvm/cia402_master.py`; `#[ignore]`d on the host, the CAN VM brings the Python): SDO
//! reads of the identity 0x1018, the device name 0x1008 and the PDO mapping, the state machine to
//! operation enabled over PDOs, CST torque that moves the plant and comes back as torque actual, a
//! fault with its EMCY and `reset_from_fault`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use frictionless_drives::can::cia402_node::DEVICE_NAME;
use frictionless_test_support::python_canopen::{PyProcess, eds, script};

const T: Duration = Duration::from_secs(120);

/// `frictl`: `/bin/frictl` in the CAN VM, else the one Cargo built for this test target.
fn frictl() -> PathBuf {
    if std::env::var_os("FRICTIONLESS_IN_CANVM").is_some() {
        return "/bin/frictl".into();
    }
    env!("CARGO_BIN_EXE_frictl").into()
}

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
#[ignore = "needs vcan and python-canopen (run tests/canvm/run.sh)"]
fn vcan_cia402_canopen_base_node_402_masters_the_emulated_drive() {
    let eds = eds();
    let mut py = PyProcess::start(
        &script("cia402_master.py"),
        &[
            "--iface",
            "vcan0",
            "--node",
            "1",
            "--eds",
            eds.to_str().unwrap(),
        ],
    );
    // The master listens before the drive boots (it waits for the boot-up).
    py.wait_line(0, T, |l| l == "listening");
    let serve = Killed(
        Command::new(frictl())
            .args([
                "sim",
                "serve",
                "--backend",
                "can",
                "--protocol",
                "cia402",
                "--bus",
                "vcan0",
            ])
            .args([
                "--preset",
                "knee",
                "--node-ids",
                "1",
                "--initial-pose-rad",
                "0",
            ])
            .args(["--duration-s", "100"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn frictl sim serve"),
    );
    py.wait_line(0, T, |l| l == "done=ok");
    drop(serve);
    let (st, lines) = py.finish(T);
    assert!(st.success(), "{lines:?}");
    let r: HashMap<&str, &str> = lines.iter().filter_map(|l| l.split_once('=')).collect();
    let get = |k: &str| *r.get(k).unwrap_or_else(|| panic!("{k} missing: {lines:?}"));
    let int = |k: &str| -> i64 {
        let v = get(k);
        v.strip_prefix("0x")
            .map_or_else(|| v.parse(), |h| i64::from_str_radix(h, 16))
            .unwrap_or_else(|e| panic!("{k}={v}: {e}"))
    };
    // Identity and name (the emulated node's dictionary; serial = node id).
    assert_eq!(
        [
            int("vendor"),
            int("product"),
            int("revision"),
            int("serial")
        ],
        [0, 0x402, 1, 1]
    );
    assert_eq!(int("device_type"), 0x0002_0192);
    assert_eq!(get("device_name").as_bytes(), DEVICE_NAME);
    assert_eq!(int("counts_per_rev"), 16384);
    assert_eq!(int("supported_modes"), 0x380);
    assert!(int("rated_torque_mnm") > 0);
    // The default PDO mapping as BaseNode402 read it by SDO.
    assert_eq!(get("rpdo1"), "0x201:6040:00+6071:00");
    assert_eq!(get("tpdo1"), "0x181:6041:00+6064:00+6077:00");
    assert_eq!(get("tpdo2"), "0x281:606C:00+60E4:01");
    assert!(
        !r.contains_key("rpdo2") && !r.contains_key("tpdo3"),
        "{lines:?}"
    );
    assert_eq!(int("op_mode"), 10);
    // State machine over PDOs.
    assert_eq!(get("state_start"), "SWITCH ON DISABLED");
    assert_eq!(get("state_enabled"), "OPERATION ENABLED");
    // CST torque: the plant moves with it; the torque comes back as 0x6077 (the measured current).
    let (p0, p1, p2) = (
        int("position_start"),
        int("position_after_plus"),
        int("position_after_minus"),
    );
    assert!(p1 > p0 + 100, "+torque: {p0} → {p1}");
    assert!(p2 < p1 - 100, "−torque: {p1} → {p2}");
    for (k, want) in [
        ("torque_actual_plus", 250),
        ("torque_actual_minus", -250),
        ("torque_actual_zero", 0),
    ] {
        assert!(
            (int(k) - want).abs() <= 25,
            "{k} = {} ‰, want {want}",
            int(k)
        );
    }
    // Fault and reset.
    assert_eq!(int("emcy"), 0x2310);
    assert_eq!(get("state_fault"), "FAULT");
    assert_eq!(int("error_code"), 0x2310);
    assert_eq!(get("state_reset"), "OPERATION ENABLED");
    assert_eq!(int("emcy_active"), 0);
    assert_eq!(int("error_code_after"), 0);
    assert_eq!(get("state_end"), "SWITCH ON DISABLED");
}

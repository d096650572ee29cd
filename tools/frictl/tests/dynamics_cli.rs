//! `frictl dynamics rnea|info` end to end: JSON lines in, JSON lines out, checked against the library.

use std::io::Write;

use crate::util::frictl_cmd as frictl;
use frictionless_dynamics::{BaseState, ExternalWrench, Force, Workspace, virtual_leg};
use nalgebra::Vector3;

fn temp_file(name: &str, text: &str) -> std::path::PathBuf {
    let dir = crate::util::scratch("frictl-dynamics-cli");
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::File::create(&p)
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
    p
}

#[test]
fn rnea_fixed_and_floating_match_the_library() {
    let cases = concat!(
        r#"{"q": {"l_knee": -0.8, "torso_pitch": 0.3}, "qd": {"l_knee": 1.5}, "qdd": {"l_ankle_roll": 2.0}}"#,
        "\n",
        r#"{"q": {"r_hip_roll": 0.4}, "base": {"pos": [0,0,1], "quat": [0, 0, 0.3826834, 0.9238795], "vel": [0.1,0,0,0,0,0.5], "acc": [0,0,0.2,0.1,0,0]}, "wrenches": {"l_sole": [10, -5, 200, 1, 2, -0.5]}}"#,
        "\n"
    );
    let path = temp_file("cases.jsonl", cases);
    let robot = virtual_leg().unwrap();
    let n = robot.dof();
    let mut ws = Workspace::new(&robot);

    // fixed base: only the first line (the second has a base, which needs --floating-base)
    let first = temp_file("first.jsonl", cases.lines().next().unwrap());
    let out = frictl()
        .args(["dynamics", "rnea", "--cases"])
        .arg(&first)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let tau_cli = line["tau"].as_object().unwrap();
    assert_eq!(tau_cli.len(), n);
    assert!(line.get("base_wrench").is_none());
    let q = robot
        .vector_from_names([("l_knee", -0.8), ("torso_pitch", 0.3)])
        .unwrap();
    let qd = robot.vector_from_names([("l_knee", 1.5)]).unwrap();
    let qdd = robot.vector_from_names([("l_ankle_roll", 2.0)]).unwrap();
    let mut tau = vec![0.0; n];
    robot.rnea(&mut ws, &q, &qd, &qdd, &mut tau).unwrap();
    for (j, name) in robot.joint_names().enumerate() {
        let got = tau_cli[name].as_f64().unwrap();
        assert!((got - tau[j]).abs() < 1e-12, "{name}");
    }

    // floating base: both lines
    let out = frictl()
        .args(["dynamics", "rnea", "--floating-base", "--cases"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 2);
    let q = robot.vector_from_names([("r_hip_roll", 0.4)]).unwrap();
    let z = vec![0.0; n];
    let base = BaseState::from_arrays(
        [0.0, 0.0, 1.0],
        [0.0, 0.0, 0.3826834, 0.9238795],
        [0.1, 0.0, 0.0, 0.0, 0.0, 0.5],
        [0.0, 0.0, 0.2, 0.1, 0.0, 0.0],
    )
    .unwrap();
    let ext = [ExternalWrench {
        frame: robot.frame_id("l_sole").unwrap(),
        wrench: Force::new(
            Vector3::new(1.0, 2.0, -0.5),
            Vector3::new(10.0, -5.0, 200.0),
        ),
    }];
    let bw = robot
        .rnea_floating(&mut ws, &base, &q, &z, &z, &ext, &mut tau)
        .unwrap();
    let got_bw: Vec<f64> = lines[1]["base_wrench"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let expect_bw = [bw.lin.x, bw.lin.y, bw.lin.z, bw.ang.x, bw.ang.y, bw.ang.z];
    for k in 0..6 {
        assert!((got_bw[k] - expect_bw[k]).abs() < 1e-9, "base_wrench[{k}]");
    }
    for (j, name) in robot.joint_names().enumerate() {
        let got = lines[1]["tau"][name].as_f64().unwrap();
        assert!((got - tau[j]).abs() < 1e-9, "{name}");
    }
}

#[test]
fn rnea_rejects_unknown_names_and_base_without_flag() {
    let bad = temp_file("bad.jsonl", r#"{"q": {"l_kne": 0.1}}"#);
    let out = frictl()
        .args(["dynamics", "rnea", "--cases"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("l_kne") && err.contains("line 1"), "{err}");

    let based = temp_file("based.jsonl", r#"{"base": {"quat": [0,0,0,1]}}"#);
    let out = frictl()
        .args(["dynamics", "rnea", "--cases"])
        .arg(&based)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--floating-base"));
}

#[test]
fn info_lists_joints_and_mass() {
    let out = frictl().args(["dynamics", "info"]).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let robot = virtual_leg().unwrap();
    for name in robot.joint_names() {
        assert!(text.contains(name), "{name} missing from info");
    }
    assert!(
        text.contains(&format!("{:.3} kg", robot.total_mass_kg())),
        "{text}"
    );
}

//! Every file a `frictl` command reads, given as a FIFO or a device: refused at once, naming the path
//! and what it is. Before, a FIFO as a URDF, robot file, ONNX/safetensors model, dataset, report, CAN
//! log or cases file blocked the command forever, and `/dev/zero` grew its memory until it died.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Runs `frictl args…`, failing the test if it is still running after a minute (a hang detector, not
/// a timing assert: each refusal happens before any read). Returns (success, stderr).
fn run(args: &[&str]) -> (bool, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while child.try_wait().unwrap().is_none() && t0.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(20));
    }
    if child.try_wait().unwrap().is_none() {
        child.kill().unwrap();
        panic!("frictl {} hung", args.join(" "));
    }
    let out = child.wait_with_output().unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn inputs_that_are_fifos_or_devices_are_refused_naming_them() {
    let dir = crate::util::scratch("frictl-files-cli");
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("input");
    let _ = std::fs::remove_file(&fifo);
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let out = |name: &str| dir.join(name).to_string_lossy().into_owned();
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/models/stress32_paper_f16_r-160.fwt"
    );
    for (path, what) in [
        (fifo.as_path(), "FIFO"),
        (Path::new("/dev/zero"), "character device"),
    ] {
        let p = &*path.to_string_lossy();
        let commands: Vec<Vec<String>> = [
            &["dynamics", "info", "--urdf", p][..],
            &["dynamics", "rnea", "--cases", p],
            &["robot", "plan", p],
            &["sim", "params", "--preset", "knee", "--params", p],
            &[
                "sim",
                "run",
                "--preset",
                "knee",
                "--current-profile",
                &format!("csv:{p}"),
                "--out",
                &out("sim.csv"),
            ],
            &["fit", "cv", p],
            &["train", "--dataset", p, "--scv", p, "--out", &out("m.fwt")],
            &[
                "search",
                "--dataset",
                p,
                "--scv",
                p,
                "--trials",
                "1",
                "--out",
                &out("search"),
            ],
            &["eval", "--dataset", p],
            &["predict", model, "--input", p],
            &["import", "onnx", p, "-o", &out("o.fwt")],
            &["import", "safetensors", p, "-o", &out("s.fwt")],
            &[
                "import",
                "csv",
                "--joint",
                "j",
                "--column",
                "time=t",
                "--column",
                "s=q",
                p,
                "-o",
                &out("c.csv"),
            ],
            &["import", "mcap", "--joint", "j", p, "-o", &out("b.csv")],
            &["can", "replay", p, "--iface", "vcan0"],
            &["inspect", p],
        ]
        .iter()
        .map(|a| a.iter().map(|s| s.to_string()).collect())
        .collect();
        for args in &commands {
            let args: Vec<&str> = args.iter().map(String::as_str).collect();
            let (ok, err) = run(&args);
            assert!(!ok, "frictl {}: succeeded", args.join(" "));
            assert!(
                err.contains(p) && err.contains(what),
                "frictl {}: the error names neither the path nor what it is: {err}",
                args.join(" ")
            );
        }
    }
    // Nothing was written for a refused input.
    for name in [
        "sim.csv", "m.fwt", "search", "o.fwt", "s.fwt", "c.csv", "b.csv",
    ] {
        assert!(!dir.join(name).exists(), "{name} was written");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

//! `examples/cpp/device.cpp` builds with a plain `c++` line against `libfrictionless.so` and runs a
//! few hundred 1 kHz ticks over three joints, with a shipped paper-size model and with CV.

use std::process::Command;

use crate::support::{crate_dir, lib_dir, run_ok, scratch};

#[test]
fn cpp_device_example_builds_and_runs() {
    let dir = scratch("cpp");
    let lib = lib_dir();
    let root = crate_dir().parent().unwrap();
    let exe = dir.join("device");
    run_ok(
        Command::new("c++")
            .args(["-std=c++17", "-O1", "-Wall", "-Wextra", "-Werror", "-I"])
            .arg(crate_dir().join("include"))
            .arg(root.join("examples/cpp/device.cpp"))
            .arg("-L")
            .arg(&lib)
            .arg("-lfrictionless")
            .arg(format!("-Wl,-rpath,{}", lib.display()))
            .args(["-pthread", "-o"])
            .arg(&exe),
    );
    let model = root.join("config/models/stress32_paper_f16_r-160.fwt");
    for with_model in [true, false] {
        let mut cmd = Command::new(&exe);
        if with_model {
            cmd.arg(&model);
        }
        let out = run_ok(cmd.args(["--ticks", "300", "--joints", "3"]));
        let text = String::from_utf8(out.stdout).unwrap();
        let last = text.lines().last().unwrap_or("");
        assert!(
            last.starts_with("ticks 300 joints 3 failures 0 "),
            "unexpected summary: {text}"
        );
        let max_i: f64 = last.rsplit(' ').next().unwrap().parse().unwrap();
        assert!(
            max_i > 0.0 && max_i <= 3.0,
            "currents within the clamp: {last}"
        );
        if with_model {
            assert!(
                text.contains("block 0: delta-theta [motor rad] x 20"),
                "{text}"
            );
        }
    }
}

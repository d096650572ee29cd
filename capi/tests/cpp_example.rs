//! `examples/cpp/device.cpp` builds with a plain `c++` line against `libfrictionless.so` and runs a
//! few hundred 1 kHz ticks over three joints, with a shipped paper-size model and with CV; with the
//! model, every joint's τ̂_F on every tick equals what frictiond computes from the same samples (the
//! core's `History`, zero until warm, then the network: `frictl predict` on the rows).

use std::fmt::Write as _;
use std::process::Command;

use fl_core::features::{History, JointSample, WarmupPolicy};
use fl_core::kernel::Mlp;

use crate::support::{close, crate_dir, frictl, lib_dir, run_ok, scratch};

/// Checks the C++ loop's trace (`joint,s,sdot,theta,omega,temperature,tau_f` per joint per tick)
/// against the core: per joint a `History` reset at its first sample (the loop's bumpless enable),
/// hold-zero warm-up, and the network on the filled rows — through the real `frictl predict` when
/// built, else the kernel call it makes.
fn check_trace(trace: &std::path::Path, model: &std::path::Path, dir: &std::path::Path) {
    let file = fl_core::weights::read_file(model).unwrap();
    let spec = file.meta.features;
    let text = std::fs::read_to_string(trace).unwrap();
    let mut per_joint: Vec<Vec<(JointSample, f64)>> = Vec::new();
    for line in text.lines() {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let k = v[0] as usize;
        if per_joint.len() <= k {
            per_joint.resize(k + 1, Vec::new());
        }
        let s = JointSample {
            s_rad: v[1],
            sdot_rad_s: v[2],
            theta_motor_rad: v[3],
            omega_motor_rad_s: v[4],
            temperature_c: v[5],
        };
        per_joint[k].push((s, v[6]));
    }
    assert_eq!(per_joint.len(), 3, "three joints traced");
    let mut mlp = Mlp::new(&file.mlp, file.dtype).unwrap();
    for (k, ticks) in per_joint.iter().enumerate() {
        let mut h = History::new(spec, file.meta.gear_ratio).unwrap();
        h.reset(&ticks[0].0);
        let mut x = vec![0.0f32; spec.n_inputs()];
        let mut rows_txt = String::new();
        let mut warm = Vec::new();
        for (s, _) in ticks {
            h.push(s);
            h.fill(&mut x).unwrap();
            warm.push(h.is_ready(WarmupPolicy::HoldZero));
            let line: Vec<String> = x.iter().map(|v| format!("{v:?}")).collect();
            writeln!(rows_txt, "{}", line.join(",")).unwrap();
        }
        let reference: Vec<f64> = match frictl() {
            Some(bin) => {
                let rows = dir.join(format!("rows{k}.csv"));
                std::fs::write(&rows, &rows_txt).unwrap();
                let out = run_ok(
                    Command::new(bin)
                        .arg("predict")
                        .arg(model)
                        .arg("--input")
                        .arg(&rows),
                );
                String::from_utf8(out.stdout)
                    .unwrap()
                    .lines()
                    .map(|l| l.trim().parse().unwrap())
                    .collect()
            }
            None => rows_txt
                .lines()
                .map(|l| {
                    let r: Vec<f32> = l.split(',').map(|x| x.parse().unwrap()).collect();
                    f64::from(mlp.forward(&r))
                })
                .collect(),
        };
        assert_eq!(reference.len(), ticks.len());
        let mut compared = 0;
        for (t, ((_, got), want)) in ticks.iter().zip(&reference).enumerate() {
            if warm[t] {
                assert!(
                    close(*got, *want, 1e-6),
                    "joint {k} tick {t}: C++ loop {got} vs frictl predict {want}"
                );
                compared += 1;
            } else {
                assert_eq!(*got, 0.0, "joint {k} tick {t}: hold-zero warm-up");
            }
        }
        assert!(
            compared > ticks.len() / 2,
            "joint {k}: {compared} warm ticks compared"
        );
    }
}

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
        let trace = dir.join("trace.csv");
        if with_model {
            cmd.arg(&model).arg("--trace").arg(&trace);
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
            check_trace(&trace, &model, &dir);
        }
    }
}

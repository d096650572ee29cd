//! Excitation-protocol tests: schedule, re-centring, guards, CSV/JSON output, determinism.

use std::path::{Path, PathBuf};
use std::process::Command;

use frictionless_acquire::protocol::{LatchReason, RunSummary};
use frictionless_acquire::{BlockKind, LogRow, Mode, ProtocolConfig, run_offline, schedule};
use frictionless_sim::PlantParams;
use frictionless_sim::params::load_table;

fn load(preset: &str, sets: &[&str]) -> (PlantParams, ProtocolConfig) {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let t = load_table(preset, None, &sets).unwrap();
    (
        PlantParams::from_table(&t).unwrap(),
        ProtocolConfig::from_table(&t).unwrap(),
    )
}

fn simulate(plant_p: &PlantParams, cfg: &ProtocolConfig, seed: u64) -> (Vec<LogRow>, RunSummary) {
    let mut rows = Vec::new();
    let run = run_offline(plant_p, cfg, &schedule(cfg), seed, &mut |r| {
        rows.push(*r);
        Ok(())
    })
    .unwrap();
    (rows, run.summary)
}

#[test]
fn schedule_plays_the_configured_amplitudes_frequencies_and_starts() {
    let (_, cfg) = load("ankle_roll", &[]);
    let blocks = schedule(&cfg);
    let scale = cfg.current_scale;
    // 5 starts × (8 amplitudes × 4 frequencies + 4 slopes × 2 directions + 6 steps) + 3 × 4 tracking
    assert_eq!(blocks.len(), 5 * (8 * 4 + 8 + 6) + 12);
    for (n, b) in blocks.iter().enumerate() {
        assert_eq!(b.chunk as usize, n, "chunks are numbered in play order");
        assert_eq!(b.recentre_s, 1.5, "re-centring before every block");
    }
    // starts: inner nodes of the range shrunk by 8°, 6 segments
    let lo = -0.4363 + 8f64.to_radians();
    let hi = 0.4363 - 8f64.to_radians();
    let per_start = 8 * 4 + 8 + 6;
    for k in 0..5 {
        let expected = lo + (hi - lo) * (k + 1) as f64 / 6.0;
        for b in &blocks[k * per_start..(k + 1) * per_start] {
            assert!((b.start_rad - expected).abs() < 1e-12);
        }
    }
    let sines: Vec<(f64, f64)> = blocks[..per_start]
        .iter()
        .filter_map(|b| match b.kind {
            BlockKind::Sine {
                amplitude_a,
                frequency_hz,
                cycles,
            } => {
                assert_eq!(cycles, 10.0);
                Some((amplitude_a, frequency_hz))
            }
            _ => None,
        })
        .collect();
    assert_eq!(sines.len(), 32);
    for (n, (a, f)) in sines.iter().enumerate() {
        let a_expected = (0.3 + 0.1 * (n / 4) as f64) * scale;
        assert!(
            (a - a_expected).abs() < 1e-9,
            "amplitude {n}: {a} vs {a_expected}"
        );
        assert_eq!(*f, [8.0, 6.0, 4.0, 2.5][n % 4], "frequencies high → low");
    }
    let ramps: Vec<f64> = blocks[..per_start]
        .iter()
        .filter_map(|b| match b.kind {
            BlockKind::Ramp { slope_a_per_s, .. } => Some(slope_a_per_s / scale),
            _ => None,
        })
        .collect();
    let want = [0.15, -0.15, 0.23, -0.23, 0.31, -0.31, 0.39, -0.39];
    assert!(
        ramps.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-12),
        "{ramps:?}"
    );
    let total_min = frictionless_acquire::protocol::schedule_duration_s(&blocks) / 60.0;
    assert!(
        (15.0..28.0).contains(&total_min),
        "ankle protocol ≥ 15 min (the project's minimum acquisition length), got {total_min}"
    );
    let (_, knee) = load("knee", &["protocol.tracking.train.enabled=false"]);
    let knee_min = frictionless_acquire::protocol::schedule_duration_s(&schedule(&knee)) / 60.0;
    assert!(
        (20.0..29.0).contains(&knee_min),
        "knee protocol without tracking ≈ 20–28 min, got {knee_min}"
    );
}

/// Per chunk: re-centring first (inactive), then the excitation; once a guard trips, every later
/// sample of that chunk is held and inactive.
#[test]
fn every_block_recentres_first_and_guards_end_the_chunk() {
    let (p, cfg) = load(
        "ankle_roll",
        &[
            "protocol.n_starts=1",
            "protocol.sines.amplitude_from_a=0.3",
            "protocol.sines.amplitude_to_a=1.0",
            "protocol.sines.amplitude_step_a=0.7",
            "protocol.sines.frequencies_hz=[0.8]",
            "protocol.ramps.slopes_a_per_s=[0.39]",
            "protocol.steps.levels_a=[0.7]",
            "protocol.tracking.train.amplitudes_rad=[0.2]",
            "protocol.tracking.train.frequencies_hz=[1.0]",
        ],
    );
    let blocks = schedule(&cfg);
    assert_eq!(blocks.len(), 2 + 2 + 1 + 1);
    let (rows, summary) = simulate(&p, &cfg, 5);
    assert_eq!(summary.samples as usize, rows.len());
    let margin = cfg.limit_margin_deg.to_radians();
    for b in &blocks {
        let chunk: Vec<&LogRow> = rows.iter().filter(|r| r.chunk == b.chunk).collect();
        let n_rec = 1500;
        let n_exc = (b.excitation_s() * 1000.0).round() as usize;
        assert_eq!(chunk.len(), n_rec + n_exc, "chunk {} length", b.chunk);
        assert!(
            chunk[..n_rec]
                .iter()
                .all(|r| r.mode == Mode::Recentre && !r.active)
        );
        let reached = chunk[n_rec].meas.s_rad;
        assert!(
            (reached - b.start_rad).abs() < 0.1,
            "chunk {}: re-centred to {reached}",
            b.chunk
        );
        let first_hold = chunk[n_rec..].iter().position(|r| r.mode == Mode::Hold);
        let excite = match b.kind {
            BlockKind::Tracking { .. } => Mode::Tracking,
            _ => Mode::Current,
        };
        let end = first_hold.map_or(chunk.len(), |h| n_rec + h);
        assert!(
            chunk[n_rec..end]
                .iter()
                .all(|r| r.mode == excite && r.active)
        );
        assert!(
            chunk[end..]
                .iter()
                .all(|r| r.mode == Mode::Hold && !r.active)
        );
        if let Some(h) = first_hold {
            let latch = summary.latches.iter().find(|l| l.chunk == b.chunk).unwrap();
            let r = chunk[n_rec + h];
            assert_eq!(latch.time_s, r.meas.time_s);
            if latch.reason == LatchReason::PositionLimit {
                assert!(
                    r.meas.s_rad <= cfg.range_lo_rad + margin
                        || r.meas.s_rad >= cfg.range_hi_rad - margin
                );
            }
        }
        // the hold keeps the joint inside the software range
        for r in &chunk {
            let s = r.truth.unwrap().state.s_rad;
            assert!(
                s > cfg.range_lo_rad - 0.02 && s < cfg.range_hi_rad + 0.02,
                "chunk {}: s = {s}",
                b.chunk
            );
        }
    }
    // the big sine (1.0 A × scale ≈ 5.3 Nm > F_s) hits the position limit; the small one (≈ 1.6 Nm) does not
    let big = blocks
        .iter()
        .find(|b| matches!(b.kind, BlockKind::Sine { amplitude_a, .. } if amplitude_a > 0.5))
        .unwrap();
    let small = blocks
        .iter()
        .find(|b| matches!(b.kind, BlockKind::Sine { amplitude_a, .. } if amplitude_a < 0.5))
        .unwrap();
    assert!(
        summary
            .latches
            .iter()
            .any(|l| l.chunk == big.chunk && l.reason == LatchReason::PositionLimit)
    );
    assert!(!summary.latches.iter().any(|l| l.chunk == small.chunk));
    // the small sine plays i0 + A sin(2π f t) exactly (i0 = 0 on the ankle), t from the block start
    let sine_rows: Vec<&LogRow> = rows
        .iter()
        .filter(|r| r.chunk == small.chunk && r.active)
        .collect();
    let BlockKind::Sine {
        amplitude_a,
        frequency_hz,
        ..
    } = small.kind
    else {
        unreachable!()
    };
    for (k, r) in sine_rows.iter().enumerate() {
        let want = amplitude_a * (std::f64::consts::TAU * frequency_hz * k as f64 * 1e-3).sin();
        assert!(
            (r.i_ref_a - want).abs() < 1e-12,
            "sample {k}: i_ref {} vs i0 + A sin = {want}",
            r.i_ref_a
        );
    }
    let peak = sine_rows
        .iter()
        .map(|r| r.i_ref_a.abs())
        .fold(0.0, f64::max);
    assert!((peak - amplitude_a).abs() < 1e-6);
}

#[test]
fn current_guard_latches_a_hold() {
    let (p, cfg) = load(
        "ankle_roll",
        &[
            "protocol.n_starts=1",
            "protocol.max_safety_current_a=0.25",
            "protocol.sines.amplitude_from_a=0.5",
            "protocol.sines.amplitude_to_a=0.5",
            "protocol.sines.frequencies_hz=[0.8]",
            "protocol.ramps.enabled=false",
            "protocol.steps.enabled=false",
            "protocol.tracking.train.enabled=false",
        ],
    );
    let (rows, summary) = simulate(&p, &cfg, 2);
    assert_eq!(summary.chunks, 1);
    let latch = summary
        .latches
        .first()
        .expect("the 0.35 A sine trips a 0.25 A guard");
    assert_eq!(latch.reason, LatchReason::Current);
    let k = rows.iter().position(|r| r.mode == Mode::Hold).unwrap();
    assert!(
        rows[k].meas.i_meas_a.abs() >= 0.25,
        "tripped on the measured current"
    );
    assert!(
        rows[..k]
            .iter()
            .filter(|r| r.active)
            .all(|r| r.meas.i_meas_a.abs() < 0.25)
    );
}

fn frictl_acquire(out: &Path, seed: u64) -> PathBuf {
    let status = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args([
            "acquire",
            "--preset",
            "ankle_roll",
            "--seed",
            &seed.to_string(),
            "--name",
            "run",
        ])
        .arg("--out")
        .arg(out)
        .args([
            "--set",
            "protocol.n_starts=1",
            "--set",
            "protocol.sines.amplitude_to_a=0.4",
            "--set",
            "protocol.sines.frequencies_hz=[0.8]",
            "--set",
            "protocol.ramps.slopes_a_per_s=[0.39]",
            "--set",
            "protocol.steps.levels_a=[0.3]",
            "--set",
            "protocol.tracking.train.amplitudes_rad=[0.1]",
            "--set",
            "protocol.tracking.train.frequencies_hz=[1.0]",
        ])
        .status()
        .unwrap();
    assert!(status.success());
    out.join("run.csv")
}

fn tmpdir(tag: &str) -> PathBuf {
    let d = crate::util::scratch(&format!("frictl-acquire-{tag}"));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn acquire_writes_documented_columns_and_a_sidecar() {
    let dir = tmpdir("cols");
    let csv_path = frictl_acquire(&dir, 3);
    let mut rd = csv::Reader::from_path(&csv_path).unwrap();
    let header: Vec<String> = rd.headers().unwrap().iter().map(str::to_owned).collect();
    for name in [
        "time_s",
        "chunk",
        "active",
        "s_rad",
        "theta_motor_rad",
        "omega_motor_rad_s",
        "i_ref_a",
        "i_meas_a",
        "temperature_c",
        "tau_f_true_nm",
        "tau_fm_nm",
        "tau_fj_nm",
        "tau_t_nm",
        "z",
        "phi_ddot",
        "gravity_nm",
    ] {
        assert!(
            header.iter().any(|h| h == name),
            "column {name} missing from {header:?}"
        );
    }
    let rows: Vec<csv::StringRecord> = rd.records().map(Result::unwrap).collect();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let times: Vec<f64> = rows
        .iter()
        .map(|r| r[col("time_s")].parse().unwrap())
        .collect();
    assert!(
        times
            .windows(2)
            .all(|w| ((w[1] - w[0]) - 1e-3).abs() < 1e-9),
        "1 kHz rows"
    );
    let mut chunks: Vec<u32> = rows
        .iter()
        .map(|r| r[col("chunk")].parse().unwrap())
        .collect();
    chunks.dedup();
    assert!(
        chunks.windows(2).all(|w| w[1] == w[0] + 1),
        "chunks are contiguous and increasing"
    );
    // ankle temperature sensor: 0.1 °C resolution
    let t: f64 = rows[10][col("temperature_c")].parse().unwrap();
    assert!(((t * 10.0).round() - t * 10.0).abs() < 1e-6);

    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    assert_eq!(side["joint"], "l_ankle_roll");
    assert_eq!(side["gear_ratio_signed"], -160.0);
    assert_eq!(side["kt_nm_per_a"], 0.0665);
    assert_eq!(side["seed"], 3);
    assert_eq!(side["chunks"].as_array().unwrap().len(), chunks.len());
    assert_eq!(
        side["summary"]["samples"].as_u64().unwrap() as usize,
        rows.len()
    );
    let cols = side["columns"].as_array().unwrap();
    assert_eq!(cols.len(), header.len());
    for (c, h) in cols.iter().zip(&header) {
        assert_eq!(c["name"].as_str().unwrap(), h);
        assert!(!c["unit"].as_str().unwrap().is_empty() && !c["doc"].as_str().unwrap().is_empty());
    }
    assert!(
        side["plant"]["sigma0_nm_per_rad"].is_number() && side["protocol"]["sines"].is_object()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn acquire_is_deterministic_for_a_seed() {
    let (a, b, c) = (tmpdir("det-a"), tmpdir("det-b"), tmpdir("det-c"));
    let fa = std::fs::read(frictl_acquire(&a, 11)).unwrap();
    let fb = std::fs::read(frictl_acquire(&b, 11)).unwrap();
    let fc = std::fs::read(frictl_acquire(&c, 12)).unwrap();
    assert!(fa == fb, "same seed, same bytes");
    assert!(fa != fc, "another seed changes noise and T0");
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
}

/// The default protocol of each preset fits its joint: most sine chunks complete instead
/// of ending at the position guard, at most half of all chunks end at a guard, the active data holds both
/// stick (|ṡ| < 0.03 rad/s, the reference's split) and sliding in a reasonable proportion, velocities
/// reach the paper's range (label filter |ṡ| < 10 rad/s; ergoCub's tracking data reaches a few rad/s),
/// and a default run gives ≥ 15 simulated minutes. Uses the simulator's true ṡ.
#[test]
fn default_protocols_fit_the_joints() {
    for preset in ["ankle_roll", "knee"] {
        let (p, cfg) = load(preset, &[]);
        let blocks = schedule(&cfg);
        let mut active = 0u64;
        let mut stick = 0u64;
        let mut fast = 0u64;
        let mut v_max = 0.0f64;
        let mut sink_rows = |r: &LogRow| {
            if r.active {
                let v = r.truth.unwrap().state.s_dot_rad_s.abs();
                active += 1;
                stick += u64::from(v < 0.03);
                fast += u64::from(v > 1.0);
                v_max = v_max.max(v);
            }
        };
        let summary = run_offline(&p, &cfg, &blocks, 1, &mut |r| {
            sink_rows(r);
            Ok(())
        })
        .unwrap()
        .summary;
        let guarded = |pred: &dyn Fn(&BlockKind) -> bool| {
            let chunks: Vec<u32> = blocks
                .iter()
                .filter(|b| pred(&b.kind))
                .map(|b| b.chunk)
                .collect();
            let hit = chunks
                .iter()
                .filter(|c| summary.latches.iter().any(|l| l.chunk == **c))
                .count();
            (hit, chunks.len())
        };
        let (sine_hit, sines) = guarded(&|k| matches!(k, BlockKind::Sine { .. }));
        let (all_hit, all) = guarded(&|_| true);
        let stick_frac = stick as f64 / active as f64;
        let fast_frac = fast as f64 / active as f64;
        eprintln!(
            "{preset}: {:.1} min, sines ending at a guard {sine_hit}/{sines}, all chunks {all_hit}/{all}, \
             stick {stick_frac:.2}, |ṡ| > 1 rad/s {fast_frac:.3}, max |ṡ| {v_max:.2} rad/s",
            summary.duration_s / 60.0
        );
        assert!(
            summary.duration_s >= 15.0 * 60.0,
            "{preset}: default run {} s < 15 min",
            summary.duration_s
        );
        assert!(
            (sine_hit as f64) < 0.3 * sines as f64,
            "{preset}: {sine_hit} of {sines} sine chunks end at a guard (most must complete)"
        );
        assert!(
            (all_hit as f64) <= 0.5 * all as f64,
            "{preset}: {all_hit} of {all} chunks end at a guard"
        );
        assert!(
            (0.25..0.75).contains(&stick_frac),
            "{preset}: stick fraction of the active samples {stick_frac}"
        );
        assert!(
            fast_frac > 0.05 && v_max > 2.0 && v_max < 10.0,
            "{preset}: velocity coverage: {fast_frac} of samples above 1 rad/s, max {v_max} rad/s"
        );
    }
}

/// `frictl acquire --sensor torque`: a torque-sensed arm's log — no motor encoder, a 500 Hz log with
/// jittered timestamps, and a joint torque sensor whose reading makes r·k_t·i − τ_joint the true
/// friction up to the reflected rotor inertia, the sensor offset and the noise.
#[test]
fn torque_sensed_arm_log_has_no_motor_encoder_and_a_consistent_torque_sensor() {
    let dir = tmpdir("torque_sensor");
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_frictl"))
            .args([
                "acquire", "--preset", "knee", "--seed", "3", "--name", "arm", "--out",
            ])
            .arg(&dir)
            .args([
                "--sensor",
                "torque",
                "--set=protocol.n_starts=1",
                "--set=protocol.sines.enabled=false",
                "--set=protocol.ramps.enabled=false",
                "--set=protocol.steps.enabled=false",
                "--set=protocol.tracking.train.amplitudes_rad=[0.4]",
                "--set=protocol.tracking.train.frequencies_hz=[0.35]",
                "--set=plant.torque_sensor.offset_nm=0.3",
            ])
            .args(extra)
            .output()
            .unwrap()
    };
    let out = run(&["--log-period-ms", "2", "--jitter-ms", "0.3"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut r = csv::Reader::from_path(dir.join("arm.csv")).unwrap();
    let header: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(
        header,
        [
            "time_s",
            "q_rad",
            "dq_rad_s",
            "current_a",
            "tau_joint_nm",
            "tau_f_true_nm"
        ],
        "knee: no temperature sensor; never a motor encoder"
    );
    let rows: Vec<Vec<f64>> = r
        .records()
        .map(|rec| rec.unwrap().iter().map(|f| f.parse().unwrap()).collect())
        .collect();
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("arm.json")).unwrap()).unwrap();
    let samples = side["summary"]["samples"].as_u64().unwrap() as usize;
    assert_eq!(rows.len(), samples.div_ceil(2), "every second 1 kHz sample");
    assert_eq!(side["columns"].as_array().unwrap().len(), header.len());
    let mut jittered = 0;
    for (k, row) in rows.iter().enumerate() {
        let dt = row[0] - 2e-3 * k as f64;
        assert!(dt.abs() <= 3e-4 + 1e-9, "row {k}: time {}", row[0]);
        if dt.abs() > 1e-6 {
            jittered += 1;
        }
        if k > 0 {
            assert!(row[0] > rows[k - 1][0], "timestamps increase");
        }
    }
    assert!(jittered > rows.len() / 2);
    // label = r·k_t·i − τ_joint; label − truth = J_eq·φ̈ − offset − noise: its mean is −offset (φ̈
    // averages out over whole tracking cycles), its spread small next to the friction.
    let (r_signed, kt) = (
        side["gear_ratio_signed"].as_f64().unwrap(),
        side["kt_nm_per_a"].as_f64().unwrap(),
    );
    let tail = &rows[rows.len() / 4..];
    let d: Vec<f64> = tail
        .iter()
        .map(|x| r_signed * kt * x[3] - x[4] - x[5])
        .collect();
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
    let truth_rms = (tail.iter().map(|x| x[5] * x[5]).sum::<f64>() / tail.len() as f64).sqrt();
    assert!((mean + 0.3).abs() < 0.1, "mean {mean}");
    assert!(sd < 0.1 * truth_rms, "sd {sd} vs truth rms {truth_rms}");
    // dq is the encoder difference: it follows the tracking velocity.
    let dq_max = tail.iter().map(|x| x[2].abs()).fold(0.0, f64::max);
    assert!(
        (dq_max - 0.4 * 2.0 * std::f64::consts::PI * 0.35).abs() < 0.3,
        "{dq_max}"
    );

    // Jitter must keep timestamps in order; the log period must be whole samples.
    for bad in [
        &["--log-period-ms", "2", "--jitter-ms", "1"][..],
        &["--log-period-ms", "1.5"],
    ] {
        let out = run(bad);
        assert!(!out.status.success(), "{bad:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

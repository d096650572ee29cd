//! `frictl acquire --live-shm` against a real `frictl sim serve` process over iceoryx2.
//!
//! - lockstep: the live log equals, row for row, an offline acquisition with the same seed (the
//!   shared-memory path is exact), and the guard ends its chunk;
//! - real time: the same protocol completes with the same chunk structure;
//! - no plant: a clear error naming the service.
//!
//! Every test uses its own iceoryx2 root directory, prefix and output directory, removed at the end.

use std::path::Path;
use std::process::{Command, Output};

use crate::plant_common;
use plant_common::{Plant, Scratch};

/// A tiny protocol on one start: two sine chunks (0.28 A and 0.71 A at 2 Hz, 2 cycles), the second
/// of which drives the ankle roll into the position guard. 2.6 s simulated.
const TINY: &[&str] = &[
    "--set",
    "protocol.n_starts=1",
    "--set",
    "protocol.sines.amplitude_from_a=0.4",
    "--set",
    "protocol.sines.amplitude_to_a=1.0",
    "--set",
    "protocol.sines.amplitude_step_a=0.6",
    "--set",
    "protocol.sines.frequencies_hz=[2.0]",
    "--set",
    "protocol.sines.cycles=2",
    "--set",
    "protocol.ramps.enabled=false",
    "--set",
    "protocol.steps.enabled=false",
    "--set",
    "protocol.tracking.train.enabled=false",
    "--set",
    "protocol.recentre_s=0.3",
];

fn acquire(s: &Scratch, seed: u64, name: &str, live: bool) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_frictl"));
    c.args([
        "acquire",
        "--preset",
        "ankle_roll",
        "--seed",
        &seed.to_string(),
    ])
    .args(TINY)
    .arg("--out")
    .arg(s.out())
    .args(["--name", name]);
    if live {
        c.args(["--live-shm", "--prefix", &s.prefix])
            .arg("--root-path")
            .arg(s.root());
    }
    let out = c.output().expect("run frictl acquire");
    assert!(
        out.status.success(),
        "acquire failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// (header, rows) of a CSV.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_owned)
        .collect();
    let rows = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    (header, rows)
}

fn sidecar(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Checks the chunk structure of a log: chunks 0, 1, … in order, each starting with re-centring
/// (mode 0, inactive); held samples (mode 2) are inactive and, once a chunk holds, it holds until
/// its end. Returns the chunks in which a hold happened.
fn check_chunks(header: &[String], rows: &[Vec<String>]) -> Vec<u32> {
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (c_chunk, c_mode, c_active) = (col("chunk"), col("mode"), col("active"));
    let mut held_chunks = Vec::new();
    let mut prev: Option<(u32, u8)> = None;
    for r in rows {
        let chunk: u32 = r[c_chunk].parse().unwrap();
        let mode: u8 = r[c_mode].parse().unwrap();
        let active: u8 = r[c_active].parse().unwrap();
        assert_eq!(active == 1, mode == 1 || mode == 3, "active ⇔ excitation");
        match prev {
            None => assert_eq!((chunk, mode), (0, 0), "starts with chunk 0 re-centring"),
            Some((pc, _)) if pc != chunk => {
                assert_eq!(chunk, pc + 1, "chunks in order");
                assert_eq!(mode, 0, "chunk {chunk} starts with re-centring");
            }
            Some((_, 2)) => assert_eq!(mode, 2, "a hold lasts until the chunk ends"),
            Some((_, pm)) => {
                if mode == 2 {
                    held_chunks.push(chunk);
                }
                assert!(mode >= pm || mode == 2, "re-centre → excite → hold");
            }
        }
        prev = Some((chunk, mode));
    }
    held_chunks
}

#[test]
fn live_lockstep_acquisition_equals_offline_acquisition_row_for_row() {
    let s = Scratch::new("ls");
    let seed = 3;
    let plant = Plant::spawn(
        &s,
        &[
            "--preset",
            "ankle_roll",
            "--lockstep",
            "--seed",
            &seed.to_string(),
        ],
    );
    acquire(&s, seed, "live", true);
    let (ok, lines) = plant.terminate();
    assert!(ok, "plant exits cleanly: {lines:?}");
    acquire(&s, seed, "offline", false);

    let (h_live, live) = read_csv(&s.out().join("live.csv"));
    let (h_off, off) = read_csv(&s.out().join("offline.csv"));
    assert!(
        !h_live.iter().any(|h| h == "tau_f_true_nm"),
        "no truth live"
    );
    assert!(h_off.iter().any(|h| h == "tau_f_true_nm"));
    assert_eq!(h_live[..], h_off[..h_live.len()], "same leading columns");
    assert_eq!(live.len(), off.len(), "same number of samples");
    assert_eq!(live.len(), 2600);
    for (k, (a, b)) in live.iter().zip(&off).enumerate() {
        assert_eq!(a[..], b[..a.len()], "row {k}");
    }
    // The run is not trivial: the joint moved and a guard fired in the second chunk.
    let held = check_chunks(&h_live, &live);
    assert_eq!(held, vec![1], "the 0.71 A sine hits the position guard");

    let j = sidecar(&s.out().join("live.json"));
    assert_eq!(j["source"], "live-shm");
    assert_eq!(j["simulated"], false);
    assert!(j["seed"].is_null());
    assert_eq!(j["live"]["first_seq"], 1);
    assert_eq!(j["live"]["states_skipped"], 0);
    assert_eq!(j["live"]["plant_publishes_sim_truth"], true);
    assert_eq!(j["summary"]["latches"][0]["chunk"], 1);
    assert_eq!(j["summary"]["latches"][0]["reason"], "position_limit");
    assert_eq!(
        j["columns"].as_array().unwrap().len(),
        h_live.len(),
        "column docs match the file"
    );
    let off_j = sidecar(&s.out().join("offline.json"));
    assert_eq!(off_j["source"], "offline-sim");
    assert_eq!(
        off_j["summary"], j["summary"],
        "same guard events and counts"
    );
}

#[test]
fn live_real_time_acquisition_completes_with_the_protocol_chunk_structure() {
    let s = Scratch::new("rt");
    let plant = Plant::spawn(&s, &["--preset", "knee,ankle_roll", "--seed", "5"]);
    let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(["acquire", "--preset", "ankle_roll"])
        .args(TINY)
        .arg("--out")
        .arg(s.out())
        .args(["--live-shm", "--joint-index", "1", "--prefix", &s.prefix])
        .arg("--root-path")
        .arg(s.root())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (ok, lines) = plant.terminate();
    assert!(ok, "{lines:?}");
    let (h, rows) = read_csv(&s.out().join("l_ankle_roll_live.csv"));
    assert_eq!(rows.len(), 2600, "one row per protocol sample");
    check_chunks(&h, &rows);
    // Time comes from the plant's seq: strictly increasing in 1 ms steps or more (skips).
    let t: Vec<f64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    assert!(t.windows(2).all(|w| w[1] - w[0] > 0.9e-3));
    let j = sidecar(&s.out().join("l_ankle_roll_live.json"));
    assert_eq!(j["live"]["joint_index"], 1);
    let received = j["live"]["states_received"].as_u64().unwrap();
    assert_eq!(received, 2601, "every exchange got a fresh state");
    // The joint was excited: s moved during the sines.
    let c_s = h.iter().position(|x| x == "s_rad").unwrap();
    let s_vals: Vec<f64> = rows.iter().map(|r| r[c_s].parse().unwrap()).collect();
    let span = s_vals.iter().cloned().fold(f64::MIN, f64::max)
        - s_vals.iter().cloned().fold(f64::MAX, f64::min);
    assert!(span > 0.05, "joint moved {span} rad");
}

#[test]
fn live_acquisition_without_a_plant_fails_naming_the_service() {
    let s = Scratch::new("none");
    let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(["acquire", "--preset", "ankle_roll"])
        .args(TINY)
        .arg("--out")
        .arg(s.out())
        .args([
            "--live-shm",
            "--connect-timeout-s",
            "0.3",
            "--prefix",
            &s.prefix,
        ])
        .arg("--root-path")
        .arg(s.root())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("{}/joint_states", s.prefix)),
        "error names the service: {err}"
    );
}

/// `frictl acquire --preset leg --live-shm` against `frictl sim serve --preset leg --lockstep`:
/// every joint driven at once over shared memory gives, row for row, the offline leg acquisition
/// with the same seed (the truth columns, offline only, aside); every joint moves.
#[test]
fn live_lockstep_leg_acquisition_equals_offline_row_for_row() {
    let s = Scratch::new("legls");
    let seed = 2;
    let tiny = [
        "--set",
        "protocol.n_starts=1",
        "--set",
        "protocol.recentre_s=0.3",
        "--set",
        "protocol.sines.amplitude_to_a=0.7",
        "--set",
        "protocol.sines.frequencies_hz=[2.0]",
        "--set",
        "protocol.sines.cycles=2",
        "--set",
        "protocol.ramps.enabled=false",
        "--set",
        "protocol.steps.levels_a=[0.8]",
        "--set",
        "protocol.steps.hold_s=0.3",
        "--set",
        "protocol.steps.rest_s=0.2",
    ];
    let run = |name: &str, live: bool| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_frictl"));
        c.args(["acquire", "--preset", "leg", "--seed", &seed.to_string()])
            .args(tiny)
            .arg("--out")
            .arg(s.out())
            .args(["--name", name]);
        if live {
            c.args(["--live-shm", "--prefix", &s.prefix])
                .arg("--root-path")
                .arg(s.root());
        }
        let out = c.output().expect("run frictl acquire");
        assert!(
            out.status.success(),
            "acquire --preset leg failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let plant = Plant::spawn(
        &s,
        &["--preset", "leg", "--lockstep", "--seed", &seed.to_string()],
    );
    run("live", true);
    let (ok, lines) = plant.terminate();
    assert!(ok, "plant exits cleanly: {lines:?}");
    run("offline", false);

    let (h_live, live) = read_csv(&s.out().join("live.csv"));
    let (h_off, off) = read_csv(&s.out().join("offline.csv"));
    assert!(
        !h_live.iter().any(|h| h.starts_with("tau_f_true")),
        "no truth live"
    );
    assert_eq!(h_off.len(), h_live.len() + 6, "six truth columns offline");
    assert_eq!(h_live[..], h_off[..h_live.len()], "same leading columns");
    assert_eq!(live.len(), off.len(), "same number of samples");
    assert!(live.len() > 1000, "{} rows", live.len());
    for (k, (a, b)) in live.iter().zip(&off).enumerate() {
        assert_eq!(a[..], b[..a.len()], "row {k}");
    }
    for j in [
        "l_hip_pitch",
        "l_hip_roll",
        "l_hip_yaw",
        "l_knee",
        "l_ankle_pitch",
        "l_ankle_roll",
    ] {
        let c = h_live.iter().position(|h| *h == format!("q_{j}")).unwrap();
        let q: Vec<f64> = live.iter().map(|r| r[c].parse().unwrap()).collect();
        let range =
            q.iter().cloned().fold(f64::MIN, f64::max) - q.iter().cloned().fold(f64::MAX, f64::min);
        assert!(range > 0.01, "{j} moved {range} rad");
    }
    let j = sidecar(&s.out().join("live.json"));
    assert_eq!(j["source"], "live-shm");
    assert!(j["seed"].is_null());
    assert_eq!(j["live"]["states_skipped"], 0);
    let off_j = sidecar(&s.out().join("offline.json"));
    for k in 0..6 {
        assert_eq!(
            off_j["joints"][k]["summary"], j["joints"][k]["summary"],
            "joint {k}: same guard events and counts"
        );
    }
}

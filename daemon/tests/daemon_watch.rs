//! Watching a running `frictiond` with the real tools: `frictl monitor --once` and
//! `frictl record --duration-s 1` against a daemon driven by a publisher thread (the plant). The
//! CSV must hold the commanded currents (= the control law), and the daemon must keep ticking with
//! fresh inputs while being watched. The `frictl` binary is the one `tests/run.sh` builds next to
//! `frictiond` (`target/<profile>/frictl`): the test is `#[ignore]`d, and `tests/run.sh` runs it with
//! `--include-ignored` (a missing binary then fails).

use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::daemon_support::*;
use frictionless_shm_types::{FLAG_STALE, STATUS_INPUT_STALE};

const TAU: [f64; 3] = [2.0, 1.0, 0.5];
const V: [f64; 3] = [0.3, 0.4, -0.2];

#[test]
#[ignore = "needs the frictl binary beside frictiond: bash tests/run.sh"]
fn monitor_and_record_see_the_daemon_without_disturbing_it() {
    let frictl = frictl_bin();
    let env = TestEnv::new("watch");
    let cfg = env.write_config(THREE_JOINTS);
    let mut d = Daemon::start(&cfg, &[]);

    // The plant: a thread publishing fixed inputs every ms (ports are !Send: opened inside).
    let stop = Arc::new(AtomicBool::new(false));
    let plant_thread = {
        let stop = stop.clone();
        let ipc = env.ipc.clone();
        std::thread::spawn(move || {
            let mut plant = Plant::open(&ipc, "plant");
            let (js, rq) = inputs(TAU, V);
            while !stop.load(Ordering::Relaxed) {
                plant.send(&js, &rq);
                std::thread::sleep(Duration::from_millis(1));
            }
        })
    };
    let want = expected(TAU, V);
    let mut obs = Plant::open(&env.ipc, "observer");
    obs.until_silent(T, |c| (0..3).all(|k| close(c.i_ref_a[k], want[k])));
    let before = obs.status_until(None, T, |s| s.ticks > 0);

    let root = env.ipc.root_path.clone().unwrap();
    let prefix = env.ipc.service_prefix.clone();

    // frictl monitor --once: one text snapshot with the models and currents per joint.
    let out = Command::new(&frictl)
        .args(["monitor", "--once", "--prefix", &prefix, "--root-path"])
        .arg(&root)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "monitor failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("frictiond: ticks"), "{text}");
    for (k, model) in [(0, "none"), (1, "cv"), (2, "scv")] {
        let line = text
            .lines()
            .find(|l| l.split_whitespace().next() == Some(&k.to_string()))
            .unwrap_or_else(|| panic!("no line for joint {k}: {text}"));
        assert!(line.contains(model), "joint {k}: {line}");
        assert!(
            line.contains(&format!("{:.4}", want[k])),
            "joint {k} current {:.4}: {line}",
            want[k]
        );
    }

    // frictl record --duration-s 1: rows with the commanded currents.
    let csv_path = env.dir.join("rec.csv");
    let out = Command::new(&frictl)
        .args([
            "record",
            "--duration-s",
            "1",
            "--joints",
            "3",
            "--prefix",
            &prefix,
            "--out",
        ])
        .arg(&csv_path)
        .arg("--root-path")
        .arg(&root)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "record failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("column {name} missing: {header:?}"))
    };
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.len() >= 50, "only {} rows in 1 s at 1 kHz", rows.len());
    let mut last_state_seq = 0u64;
    for (n, r) in rows.iter().enumerate() {
        assert_eq!(r.len(), header.len(), "row {n}");
        let seq: u64 = r[col("state_seq")].parse().unwrap();
        assert!(seq >= last_state_seq, "row {n}: state_seq went back");
        last_state_seq = seq;
        for k in 0..3 {
            let i: f64 = r[col(&format!("j{k}_i_ref_a"))].parse().unwrap();
            let flags: u32 = r[col(&format!("j{k}_flags"))].parse().unwrap();
            assert!(close(i, want[k]), "row {n} joint {k}: {i} vs {}", want[k]);
            assert_eq!(flags & FLAG_STALE, 0, "row {n} joint {k}");
            let tau: f64 = r[col(&format!("j{k}_tau_des_nm"))].parse().unwrap();
            assert_eq!(
                tau, TAU[k],
                "row {n} joint {k}: the request is recorded too"
            );
        }
    }

    // The daemon kept ticking on fresh inputs while watched.
    let after = obs.status_until(None, T, |s| s.ticks > before.ticks + 1000);
    assert_eq!(after.flags & STATUS_INPUT_STALE, 0);
    assert!(d.alive());
    eprintln!(
        "while watched: ticks {} → {}, missed deadlines {} → {}, stale ticks {} → {}",
        before.ticks,
        after.ticks,
        before.missed_deadlines,
        after.missed_deadlines,
        before.stale_ticks,
        after.stale_ticks
    );
    stop.store(true, Ordering::Relaxed);
    plant_thread.join().unwrap();
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
}

//! Fuzz target: the robot-log importers of `frictionless-logs` as `frictl import csv|mcap` calls them:
//! `CsvSpec::parse` (the `--column`/`--unit`/`--negate` texts) + `csv_log::read`, and
//! `mcap_log::parse_effort` (the `--effort` text) + `mcap_log::read` (ROS 2 `JointState` bags).
//! `.mat` (HDF5 through the C library) has its own target, `mat_import`.
//!
//! Input: a spec, then (after the first 0xFF byte, which never occurs in UTF-8) the log file's bytes;
//! without a 0xFF byte the whole input is the file and the spec is empty. The spec is text, one
//! directive per line, so the fuzzer explores roles, units, signs and names too:
//! - `c ROLE=COLUMN` (a `--column`), `u ROLE=UNIT` (a `--unit`), `n ROLE` (a `--negate`),
//!   `d X` (the delimiter: the first byte of X, ASCII only, as frictl requires);
//! - `t TOPIC`, `j JOINT`, `e ROLE|none` (the MCAP topic, joint and `--effort`; a role `--effort`
//!   refuses is passed to `mcap_log::read` as well, which must refuse it too);
//! - `b N`: the streamed MCAP read's rows per block (default 7).
//!
//! Without `c` lines the CSV header's columns are mapped in order to `time`, `s`, `sdot`, … (every
//! role, in canonical order). MCAP defaults: topic `/joint_states`, joint `wrist`, effort `tau_joint`.
//!
//! Both readers run on every input, the MCAP one whole and streamed (`mcap_log::read_streamed`, whose
//! blocks must hold the whole read's rows): each must return a run or an error naming the file, never panic,
//! and an accepted run must hold one finite value per row in every signal with strictly increasing
//! time and a report that counts what it used.
#![no_main]

use frictionless_logs::Role;
use frictionless_logs::csv_log::{self, CsvSpec};
use frictionless_logs::mcap_log::{self, McapSpec};
use libfuzzer_sys::fuzz_target;

#[path = "common/log_import.rs"]
mod log_import;
use log_import::{check, scratch_dir};

fuzz_target!(|data: &[u8]| {
    let (spec, file) = match data.iter().position(|&b| b == 0xFF) {
        Some(i) => (
            String::from_utf8_lossy(&data[..i]).into_owned(),
            &data[i + 1..],
        ),
        None => (String::new(), data),
    };
    let (mut columns, mut units, mut negate) = (Vec::new(), Vec::new(), Vec::new());
    let mut delimiter = b',';
    let mut block_rows: usize = 7;
    let (mut topic, mut joint, mut effort) = (
        "/joint_states".to_string(),
        "wrist".to_string(),
        "tau_joint".to_string(),
    );
    for line in spec.lines() {
        let (key, value) = line.split_once(' ').unwrap_or((line, ""));
        match key {
            "c" => columns.push(value.to_string()),
            "u" => units.push(value.to_string()),
            "n" => negate.push(value.to_string()),
            "d" => {
                if let Some(&b) = value.as_bytes().first().filter(|b| b.is_ascii()) {
                    delimiter = b;
                }
            }
            "t" => topic = value.to_string(),
            "j" => joint = value.to_string(),
            "e" => effort = value.to_string(),
            "b" => block_rows = value.trim().parse().unwrap_or(block_rows).clamp(1, 1 << 16),
            _ => {}
        }
    }
    if columns.is_empty() {
        // The header's columns in order → every role in canonical order.
        let header = file.split(|&b| b == b'\n').next().unwrap_or(&[]);
        columns = header
            .split(|&b| b == delimiter)
            .zip(Role::ALL)
            .map(|(col, role)| format!("{role}={}", String::from_utf8_lossy(col).trim()))
            .collect();
    }
    let mut no_progress = |_: u64, _: u64| {};

    let csv_path = scratch_dir().join("log.csv");
    std::fs::write(&csv_path, file).expect("write scratch CSV");
    if let Ok(mut sp) = CsvSpec::parse(&columns, &units, &negate) {
        sp.delimiter = delimiter;
        if let Ok(run) = csv_log::read(&csv_path, &sp, &mut no_progress) {
            check(&run);
        }
    }

    let mcap_path = scratch_dir().join("log.mcap");
    std::fs::write(&mcap_path, file).expect("write scratch MCAP");
    // frictl's `--effort` check, then any role (`read` refuses the ones that are not an effort).
    let effort_role = match mcap_log::parse_effort(&effort) {
        Ok(r) => r,
        Err(_) => match Role::parse(&effort) {
            Ok(role) => Some(role),
            Err(_) => return,
        },
    };
    let Ok(negate) = negate
        .iter()
        .map(|n| Role::parse(n))
        .collect::<Result<Vec<_>, _>>()
    else {
        return;
    };
    let sp = McapSpec {
        topic,
        joints: vec![joint],
        all_joints: false,
        state_joints: None,
        effort_role,
        negate,
    };
    let whole = mcap_log::read(&mcap_path, &sp, &mut no_progress);
    if let Ok(run) = &whole {
        check(run);
    }
    // Streamed (`--window-samples`): blocks of `block_rows` rows, each of one length in every
    // signal; when the read succeeds, the blocks hold every used row, the whole read's if it
    // succeeded too.
    let mut times: Vec<f64> = Vec::new();
    let mut sink = |b: frictionless_logs::ImportedRun| {
        let n = b.signals.time_s.len();
        assert!(
            n >= 1 && n <= block_rows,
            "a block of {n} rows (at most {block_rows})"
        );
        assert!(
            signal_lengths(&b.signals).all(|len| len == n),
            "one length per block"
        );
        times.extend_from_slice(&b.signals.time_s);
        Ok(())
    };
    let stream = frictionless_logs::BlockSink {
        block_rows,
        sink: &mut sink,
    };
    let extra = mcap_log::McapState::default();
    let streamed = mcap_log::read_streamed(&mcap_path, &sp, &extra, &mut no_progress, Some(stream));
    if let Ok(run) = &streamed {
        assert_eq!(
            times.len() as u64,
            run.report.rows_used,
            "every used row in a block"
        );
        if let Ok(w) = &whole {
            assert_eq!(
                times, w.signals.time_s,
                "the streamed rows are the whole read's"
            );
        }
    }
});

/// The lengths of the signals a run holds, and of its chunk ids.
fn signal_lengths(s: &frictionless_logs::RunSignals) -> impl Iterator<Item = usize> + '_ {
    log_import::signals(s)
        .into_iter()
        .flatten()
        .map(Vec::len)
        .chain([s.chunk.len()])
}

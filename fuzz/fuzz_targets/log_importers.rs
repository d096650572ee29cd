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
//!   refuses is passed to `mcap_log::read` as well, which must refuse it too).
//!
//! Without `c` lines the CSV header's columns are mapped in order to `time`, `s`, `sdot`, … (every
//! role, in canonical order). MCAP defaults: topic `/joint_states`, joint `wrist`, effort `tau_joint`.
//!
//! Both readers run on every input: each must return a run or an error naming the file, never panic,
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
    if let Ok(run) = mcap_log::read(&mcap_path, &sp, &mut no_progress) {
        check(&run);
    }
});

//! The robot workflow as the README and `docs/robot-workflow.md` write it, run as written on one
//! recording: each document's first `sh` block after its workflow heading, line by line, through
//! `sh -c` in a scratch directory with this build's `frictl` and `frictiond` first on `PATH`.
//!
//! What is not run as written, and why:
//! - the live acquisition (`frictl acquire … --live-shm`): its full protocol lasts 19 min in real
//!   time, so the same line runs offline against the virtual ankle roll (the `--live-shm`,
//!   `--prefix` and `--joint-index` options left out) with a short protocol; `acquire_live` tests
//!   the live path;
//! - the `# optional` search (a 40-trial search; `search_cli` tests it);
//! - the lines that need a robot computer: `sudo …` (the package under systemd:
//!   `tests/systemd-vm/run.sh`) and `frictl monitor` (a live daemon).
//!
//! The files the blocks name come from the scratch directory: `robot.urdf` is the virtual leg's URDF
//! (it has `l_ankle_roll`), `config/` is the repository's, and `new_log.csv` (the README's drift
//! check) is a second recording of another seed, labelled like the first.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::util::{EPOCH, SMALL_PROTOCOL};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .unwrap()
        .to_path_buf()
}

/// The command lines of the first `sh` block after `heading` in `doc` (comments and blank lines
/// left out, `\` continuations joined); each with whether its comment says `optional`.
fn block(doc: &str, heading: &str) -> Vec<(String, bool)> {
    let text = std::fs::read_to_string(repo().join(doc)).unwrap();
    let after = &text[text
        .find(heading)
        .unwrap_or_else(|| panic!("{doc}: no `{heading}`"))..];
    let start = after.find("```sh\n").expect("an sh block") + 6;
    let body = &after[start..start + after[start..].find("```").unwrap()];
    let mut out = Vec::new();
    let mut pending = String::new();
    for line in body.lines() {
        let line = line.trim();
        if line.starts_with('#') || line.is_empty() {
            continue;
        }
        if let Some(head) = line.strip_suffix('\\') {
            pending.push_str(head);
            continue;
        }
        pending.push_str(line);
        let (cmd, comment) = match pending.split_once(" #") {
            Some((c, k)) => (c.trim().to_owned(), k.to_owned()),
            None => (pending.trim().to_owned(), String::new()),
        };
        out.push((cmd, comment.contains("optional")));
        pending.clear();
    }
    out
}

/// Runs `line` with `sh -c` in `dir`, this build's binaries first on `PATH`; fails the test with
/// its output unless it exits 0.
fn sh(dir: &Path, line: &str) {
    let bin = Path::new(env!("CARGO_BIN_EXE_frictl")).parent().unwrap();
    assert!(
        bin.join("frictiond").is_file(),
        "frictiond next to frictl (cargo build --workspace --bins, as tests/run.sh)"
    );
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new("sh")
        .arg("-c")
        .arg(line)
        .current_dir(dir)
        .env("PATH", path)
        .env("SOURCE_DATE_EPOCH", EPOCH)
        // As a user's shell: not a `cargo run` child (frictl would build frictiond with cargo).
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .output()
        .expect("sh runs");
    assert!(
        out.status.success(),
        "`{line}` failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The acquisition line offline: without the live options, with the short protocol and `seed`,
/// and `name` instead of the line's `--name` where given.
fn offline_acquisition(line: &str, seed: u64, name: Option<&str>) -> String {
    let mut words: Vec<&str> = line.split_whitespace().collect();
    let mut left_out = vec!["--prefix", "--joint-index"];
    if name.is_some() {
        left_out.push("--name");
    }
    for opt in left_out {
        if let Some(k) = words.iter().position(|w| *w == opt) {
            words.drain(k..k + 2);
        }
    }
    words.retain(|w| *w != "--live-shm");
    let extra = match name {
        Some(n) => format!("--seed {seed} --name {n}"),
        None => format!("--seed {seed}"),
    };
    let sets: Vec<String> = SMALL_PROTOCOL
        .iter()
        .map(|s| format!("--set '{s}'"))
        .collect();
    format!("{} {} {extra}", words.join(" "), sets.join(" "))
}

/// Runs one document's block in a fresh scratch directory; returns the commands run (the first two
/// words of each) and the directory.
fn run_block(doc: &str, heading: &str, tag: &str) -> (Vec<String>, Scratch) {
    let scratch =
        Scratch(std::env::temp_dir().join(format!("fl_docs_{tag}_{}", std::process::id())));
    let dir = scratch.0.clone();
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::os::unix::fs::symlink(repo().join("config"), dir.join("config")).unwrap();
    std::fs::copy(
        repo().join("config/urdf/virtual_leg.urdf"),
        dir.join("robot.urdf"),
    )
    .unwrap();
    let mut ran = Vec::new();
    let mut acquired = false;
    for (line, optional) in block(doc, heading) {
        if optional || line.starts_with("sudo ") || line.starts_with("frictl monitor") {
            continue;
        }
        let run = if line.starts_with("frictl acquire") && line.contains("--live-shm") {
            acquired = true;
            offline_acquisition(&line, 3, None)
        } else {
            line.clone()
        };
        if line.contains("new_log.csv") && !dir.join("new_log.csv").exists() {
            // Another day's recording of the same joint, labelled like the first.
            let first = block(doc, heading)
                .into_iter()
                .map(|(l, _)| l)
                .find(|l| l.starts_with("frictl acquire"))
                .unwrap();
            sh(&dir, &offline_acquisition(&first, 4, Some("later")));
            sh(
                &dir,
                "frictl preprocess later.csv --urdf robot.urdf --joint l_ankle_roll -o new_log.csv",
            );
        }
        sh(&dir, &run);
        ran.push(
            line.split_whitespace()
                .take(2)
                .collect::<Vec<_>>()
                .join(" "),
        );
    }
    assert!(acquired, "{doc}: no live acquisition line");
    (ran, scratch)
}

/// The scratch directory of one block, removed on drop (also when the test fails).
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap_or_else(|e| {
        panic!("{}: {e}", path.display());
    }))
    .unwrap()
}

/// What both blocks must have done, checked on their outputs.
fn check_outputs(ran: &[String], dir: &Path) {
    for cmd in [
        "frictl acquire",
        "frictl preprocess",
        "frictl fit",
        "frictl train",
        "frictl eval",
        "frictl config",
        "frictiond --config",
        "frictl replay",
    ] {
        assert!(ran.iter().any(|r| r == cmd), "`{cmd}` not run: {ran:?}");
    }
    // Training held out a test set of the one recording (its chunks, or time blocks of it).
    let report = json(&dir.join("l_ankle_roll.train.json"));
    assert!(
        report["split"]["test"]
            .as_array()
            .is_some_and(|t| !t.is_empty()),
        "the train report names its test set: {}",
        report["split"]
    );
    let replay = json(&dir.join("replay/replay.json"));
    let text = replay.to_string();
    assert!(text.contains("l_ankle_roll"), "{text}");
    let config = std::fs::read_to_string(dir.join("frictiond.toml")).unwrap();
    assert!(config.contains("ood = \"static\""), "{config}");
}

#[test]
fn the_robot_workflow_document_runs_as_written_on_one_recording() {
    let (ran, dir) = run_block(
        "docs/robot-workflow.md",
        "## Record, label, fit, train, deploy",
        "workflow",
    );
    check_outputs(&ran, &dir.0);
}

#[test]
fn the_readme_workflow_runs_as_written_on_one_recording() {
    let (ran, dir) = run_block("README.md", "## Workflow on a real robot", "readme");
    check_outputs(&ran, &dir.0);
    assert!(
        ran.iter().filter(|r| *r == "frictl eval").count() == 2,
        "the held-out evaluation and the drift check: {ran:?}"
    );
}

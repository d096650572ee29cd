//! What the frictl test modules share: running the `frictl` binary as a process, checking its exit,
//! and the small acquisition protocol most tests start from.

#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The `SOURCE_DATE_EPOCH` every run gets, so the timestamps frictl writes are reproducible.
pub const EPOCH: &str = "1700000000";

/// The `frictl` binary of this build, ready for arguments.
pub fn frictl_cmd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_frictl"));
    c.env("SOURCE_DATE_EPOCH", EPOCH);
    c
}

/// Runs `frictl ARGS` to the end and returns its output, whatever its exit.
pub fn frictl(args: &[&str]) -> Output {
    frictl_cmd().args(args).output().expect("frictl runs")
}

/// Runs `frictl ARGS` and fails the test, with frictl's stderr, unless it exits 0.
pub fn frictl_ok(args: &[&str]) -> Output {
    ok(frictl(args), &format!("frictl {args:?}"))
}

/// Fails the test, naming `what` and showing the stderr, unless `out` is a success.
pub fn ok(out: Output, what: &str) -> Output {
    assert!(
        out.status.success(),
        "{what} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Fails the test unless `out` is a failure; returns its stderr.
pub fn err_text(out: Output, what: &str) -> String {
    assert!(!out.status.success(), "{what} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A path as a `&str` argument (test paths are UTF-8).
pub fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// The `--set` overrides that cut a preset's excitation protocol down to one start with one sine
/// frequency, one ramp slope, one step level and one tracking sine: a few seconds of data.
pub const SMALL_PROTOCOL: [&str; 6] = [
    "protocol.n_starts=1",
    "protocol.sines.frequencies_hz=[0.8]",
    "protocol.ramps.slopes_a_per_s=[0.39]",
    "protocol.steps.levels_a=[0.3]",
    "protocol.tracking.train.amplitudes_rad=[0.1]",
    "protocol.tracking.train.frequencies_hz=[1.0]",
];

/// The arguments of `frictl acquire` for [`SMALL_PROTOCOL`] on `preset`, seeded, writing
/// `OUT/NAME.csv` and its sidecar, followed by `--set` for each of `extra`.
pub fn small_acquire_args<'a>(
    preset: &'a str,
    seed: &'a str,
    out: &'a Path,
    name: &'a str,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "acquire",
        "--preset",
        preset,
        "--seed",
        seed,
        "--name",
        name,
        "--out",
        s(out),
    ];
    for set in SMALL_PROTOCOL.iter().chain(extra) {
        args.extend_from_slice(&["--set", set]);
    }
    args
}

/// A scratch directory of this test process, `NAME-PID`, under cargo's target tmp dir (not the
/// system's /tmp, which the tests would otherwise fill run after run). The first call of a process
/// removes the directories left by test processes that are no longer running.
pub fn scratch(name: &str) -> std::path::PathBuf {
    static SWEPT: std::sync::Once = std::sync::Once::new();
    let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("frictl-tests");
    SWEPT.call_once(|| {
        let Ok(entries) = std::fs::read_dir(&root) else {
            return;
        };
        for e in entries.flatten() {
            let file_name = e.file_name();
            let Some(pid) = file_name
                .to_str()
                .and_then(|n| n.rsplit_once('-'))
                .and_then(|(_, pid)| pid.parse::<u32>().ok())
            else {
                continue;
            };
            if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
                let _ = std::fs::remove_dir_all(e.path());
            }
        }
    });
    let dir = root.join(format!("{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    dir
}

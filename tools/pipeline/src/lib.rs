//! # `frictionless-pipeline`: the pipelines that chain frictl's stages
//!
//! What it **is**: `frictl demo` (two independent joints, a torque-sensed joint, the coupled leg,
//! on-policy rounds; [`demo`]) and `frictl robot run|plan` ([`robot_run`], over the robot file
//! description [`robot`]). Each stage runs as a child `frictl` process built from its typed `Args`
//! (`frictl_cli::stage::argv`), with its own log and its own signal handling; the path of the
//! `frictl` executable to start is a parameter ([`Host::frictl`]).
//!
//! What it is **not**: the stages themselves (the `frictl` binary and the library crates of
//! `tools/` do the work) or a command-line parser (`frictl-cli`). It never depends on the daemon:
//! the experiments start `frictiond` as a process.

#![warn(missing_docs)]

use std::path::{Path, PathBuf};

pub mod demo;
pub mod robot;
pub mod robot_run;

/// Makes the child `cmd` starts die with this process: `PR_SET_PDEATHSIG = SIGTERM` set in the child
/// before it runs, so a stage (e.g. a long `frictl search`) does not outlive a pipeline killed
/// outright (SIGKILL, the OOM killer) and a rerun never finds it still writing into the directory.
/// A child whose parent already died before the call exits at once. The signal is sent when the
/// thread that spawned the child ends: spawn from a thread that outlives the child (the pipelines
/// spawn and wait on one thread).
pub fn die_with_parent(cmd: &mut std::process::Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: getpid before the fork; in the child only prctl, getppid and _exit run, all
    // async-signal-safe, with no allocation or lock.
    let parent = unsafe { libc::getpid() };
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::getppid() != parent {
                libc::_exit(1);
            }
            Ok(())
        });
    }
}

/// What a pipeline needs from the `frictl` that runs it, beyond the command lines of its stages.
pub trait Host {
    /// The `frictl` executable every stage runs as (`frictl` passes `std::env::current_exe()`).
    fn frictl(&self) -> anyhow::Result<PathBuf>;

    /// `frictl distill` in process, through its typed entry: writes the student to `args.out`
    /// only when the held-out gate passes.
    fn distill(&self, args: &frictl_cli::distill::Args) -> anyhow::Result<Distilled>;

    /// The command line of `frictl import csv` (its arguments live in the binary).
    fn import_csv_argv(&self, import: &ImportCsv<'_>) -> anyhow::Result<Vec<String>>;
}

/// What the in-process distillation ([`Host::distill`]) did.
#[derive(Debug)]
pub struct Distilled {
    /// The held-out gate (overall first, then per |ṡ| band).
    pub gate: frictionless_train::distill::Gate,
    /// Whether the student passed and was written.
    pub written: bool,
    /// The student (written only when `written`).
    pub model: frictionless::weights::ModelFile,
    /// Hot and cold inference time of the teacher on this CPU \[µs\].
    pub teacher_us: Option<(f64, f64)>,
    /// Hot and cold inference time of the student \[µs\].
    pub student_us: Option<(f64, f64)>,
}

/// The label of a `frictl import csv` stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImportLabel {
    /// `--label torque-sensor`: from the joint torque sensor.
    TorqueSensor,
    /// `--label given`: a column of the log.
    Given,
}

/// A `frictl import csv` stage ([`Host::import_csv_argv`]); every other argument keeps its default.
#[derive(Clone, Debug)]
pub struct ImportCsv<'a> {
    /// The CSV logs.
    pub files: &'a [PathBuf],
    /// `--joint`.
    pub joint: &'a str,
    /// `--column KEY=NAME` mappings.
    pub columns: &'a [String],
    /// The dataset to write.
    pub out: &'a Path,
    /// `--label`.
    pub label: ImportLabel,
    /// `--gear-ratio` (signed).
    pub gear_ratio_signed: f64,
    /// `--kt` \[Nm/A\].
    pub kt_nm_per_a: f64,
}

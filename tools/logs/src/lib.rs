//! # `frictionless-logs`: robot logs in
//!
//! Crate table: `tools/logs`; depends on `frictionless-ident` (its [`RunSignals`] is what this crate
//! produces), `frictionless-dataset` and `frictionless` (its [`frictionless::regular_file`] opens);
//! used by `frictl import csv|mat|mcap`.
//!
//! What this crate **is**: readers that turn the labelled joints of a robot's log into one in-memory
//! time series per signal per joint per run ([`ImportedRun`]: time [s], s, ṡ, s̈, θ, ω, current,
//! τ_joint, τ_motor, τ_F, temperature, each optional), plus, for the whole-body τ_ID, the positions of
//! every joint the log has ([`JointStates`], matched to the URDF's names), in SI units and the
//! project's signs, with a record of every conversion ([`RunReport`]):
//! - [`csv_log`]: any CSV with a column → [`Role`] mapping and per-role [`Unit`]s, streamed row by row;
//! - [`mcap_log`]: ROS 2 MCAP bags of `sensor_msgs/msg/JointState` (CDR; the whole-body state also
//!   from `sensor_msgs/msg/Imu` and `geometry_msgs/msg/WrenchStamped` topics), streamed record by record;
//! - `mat_log` (cargo feature `mat`, needs the system HDF5 library): the YARP robot logger's MATLAB
//!   v7.3 files, read one column of one dataset at a time.
//!
//! Every reader counts and drops rows with a non-finite value (per column) and rows whose time goes
//! back (an error above 1 % of the rows), refuses a path that is not a regular file (a FIFO or a
//! device), and never holds more than the labelled joints' signals and the joint positions in memory.
//!
//! What it is **not**: a resampler, filter or labeller. The uniform grid, the chunk split, the
//! Butterworth, the Kalman smoother and the friction label are `frictionless-ident`'s
//! ([`frictionless_ident::preprocess::preprocess_signals`]); the dataset files are
//! `frictionless-dataset`'s.

#![warn(missing_docs)]

pub mod csv_log;
#[cfg(feature = "mat")]
pub mod mat_log;
mod mcap_cdr;
pub mod mcap_log;
mod mcap_state;
pub mod plausibility;
mod roles;
mod run;

pub use frictionless_ident::preprocess::{JointStates, RunSignals};
pub use roles::{Role, Unit};
pub use run::{
    BlockSink, ImportedRun, RoleMap, RunReport, StateLayout, WRENCH_COMPONENTS, label_sign_warning,
    unique_run_names,
};

use std::fs::File;
use std::path::Path;

/// Import errors; each names the file, and the line, column or value where one applies.
#[derive(Debug, thiserror::Error)]
pub enum LogsError {
    /// The file could not be opened or read.
    #[error("{path}: {msg}")]
    Io {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// The path is not a regular file (FIFO, device, directory).
    #[error("{path}: not a regular file ({file_type}); a FIFO, device or directory is refused")]
    NotRegular {
        /// File.
        path: String,
        /// What it is instead, e.g. "FIFO", "character device", "directory".
        file_type: &'static str,
    },
    /// The file has no data.
    #[error("{path}: {what}")]
    Empty {
        /// File.
        path: String,
        /// What is missing (`empty file`, `no data rows`, …).
        what: String,
    },
    /// A column an option names (`--base-quat`, `--wrench`) is not in the header.
    #[error(
        "{path}: column `{column}` (of {option}) is not in the header; the header has: {header}"
    )]
    MissingOptionColumn {
        /// File.
        path: String,
        /// Column name asked for.
        column: String,
        /// The option naming it, e.g. `--base-quat`.
        option: String,
        /// The header, comma separated.
        header: String,
    },
    /// A mapped column is not in the header.
    #[error(
        "{path}: column `{column}` (role {role}) is not in the header; the header has: {header}"
    )]
    MissingColumn {
        /// File.
        path: String,
        /// Column name asked for.
        column: String,
        /// Role it was mapped to.
        role: Role,
        /// The header's column names, comma-separated.
        header: String,
    },
    /// A role name is unknown.
    #[error("unknown role `{value}`; accepted roles: {accepted}")]
    UnknownRole {
        /// The text given.
        value: String,
        /// The accepted role names.
        accepted: String,
    },
    /// A unit is unknown or does not fit the role.
    #[error("unit `{value}` does not fit role {role}; accepted units: {accepted}")]
    UnknownUnit {
        /// Role.
        role: Role,
        /// The text given.
        value: String,
        /// The accepted units for that role.
        accepted: String,
    },
    /// A role is mapped twice.
    #[error("role {role} is mapped twice (`{first}` and `{second}`)")]
    DuplicateRole {
        /// Role.
        role: Role,
        /// First mapping.
        first: String,
        /// Second mapping.
        second: String,
    },
    /// A malformed `--column`/`--unit` argument or another usage problem.
    #[error("{0}")]
    Usage(String),
    /// A field that is not a number.
    #[error("{path}: line {line}, column `{column}`: cannot parse {value:?} as a number")]
    Parse {
        /// File.
        path: String,
        /// 1-based line.
        line: u64,
        /// Column.
        column: String,
        /// Raw text (at most 64 characters).
        value: String,
    },
    /// Too many rows go back in time.
    #[error(
        "{path}: time goes back on {count} of {rows} rows (more than 1 %), first at {where_}; sort the log or check the time column"
    )]
    NonMonotonic {
        /// File.
        path: String,
        /// Rows dropped.
        count: u64,
        /// Rows read.
        rows: u64,
        /// Where the first one is (`line 17`, `message 3`).
        where_: String,
    },
    /// The file's content does not fit the format.
    #[error("{path}: {msg}")]
    Format {
        /// File.
        path: String,
        /// Reason.
        msg: String,
    },
    /// The joint is not in the log.
    #[error("{path}: joint `{joint}` not found; the log has: {available}")]
    JointNotFound {
        /// File.
        path: String,
        /// Joint asked for.
        joint: String,
        /// Names present, comma-separated.
        available: String,
    },
}

impl LogsError {
    fn io(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::Io {
            path: path.display().to_string(),
            msg: e.to_string(),
        }
    }
}

/// Opens `path` for reading only if it is a regular file ([`frictionless::regular_file::open`]: a
/// FIFO never blocks, a device is refused before a byte is read).
pub fn open_regular(path: &Path) -> Result<File, LogsError> {
    use frictionless::regular_file::{self, Refused};
    match regular_file::open(path) {
        Ok((file, _)) => Ok(file),
        Err(e) => match Refused::of(&e) {
            Some(&Refused::NotRegular { file_type }) => Err(LogsError::NotRegular {
                path: path.display().to_string(),
                file_type,
            }),
            _ => Err(LogsError::io(path, e)),
        },
    }
}

/// A progress callback: `(bytes or rows done, total)`. Readers call it every so often; the command
/// layer draws a bar on a terminal.
pub type Progress<'a> = &'a mut dyn FnMut(u64, u64);

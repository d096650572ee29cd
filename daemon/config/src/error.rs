//! The error of a configuration and the [`Checker`] that builds one naming the file, the key and
//! the value. Every module that checks a section uses both; this module uses none of them.

use std::path::{Path, PathBuf};

/// Why a configuration is not acceptable. Every variant names the file; most name the key and value.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// Config file.
        file: PathBuf,
        /// OS error.
        source: std::io::Error,
    },
    /// TOML syntax, a wrong type or an unknown key.
    #[error("{file}: {message}")]
    Parse {
        /// Config file.
        file: PathBuf,
        /// toml's message (names the key, line and column).
        message: String,
    },
    /// A key holds a value outside its domain.
    #[error("{file}: key `{key}` = {value}: {requirement}")]
    Invalid {
        /// Config file.
        file: PathBuf,
        /// Full key path, e.g. `joint[1].max_curr`.
        key: String,
        /// The offending value as written.
        value: String,
        /// What it must satisfy.
        requirement: String,
    },
    /// A model file is missing or invalid.
    #[error("{file}: key `{key}` = {path:?}: {message}")]
    Model {
        /// Config file.
        file: PathBuf,
        /// Key path, e.g. `joint[0].model`.
        key: String,
        /// Resolved model path.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
}

pub(crate) struct Checker<'a> {
    pub(crate) file: &'a Path,
}

impl Checker<'_> {
    pub(crate) fn fail(
        &self,
        key: String,
        value: impl std::fmt::Display,
        req: &str,
    ) -> ConfigError {
        ConfigError::Invalid {
            file: self.file.to_path_buf(),
            key,
            value: value.to_string(),
            requirement: req.to_owned(),
        }
    }
    pub(crate) fn finite_pos(&self, key: String, v: f64) -> Result<(), ConfigError> {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(self.fail(key, v, "must be finite and > 0"))
        }
    }
    pub(crate) fn nonneg(&self, key: String, v: f64) -> Result<(), ConfigError> {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(self.fail(key, v, "must be finite and >= 0"))
        }
    }
}

//! The daemon's configuration: the `frictiond-config` crate, re-exported so daemon modules keep
//! writing `crate::config::…`.

pub use frictiond_config::*;

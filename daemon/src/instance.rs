//! One `frictiond` per service prefix: an advisory lock file held for the process's lifetime.
//!
//! What this module **is**: [`InstanceLock`], an exclusive `flock(2)` on
//! `<iceoryx2 root>/frictiond-<hash of the prefix>.lock` (the root is `[backend] root_path`, else
//! iceoryx2's default root). The holder writes its PID and prefix into the file; a second daemon on
//! the same root and prefix fails to take the lock and refuses to start, naming the prefix, the lock
//! file and the first one's PID. The kernel drops the lock when the holder exits in any way (crash,
//! SIGKILL), so a stale file never blocks a restart. Both backends publish on the prefix's services,
//! so both take the lock.
//!
//! What it is **not**: no protection against a process that is not `frictiond` publishing commands
//! (iceoryx2 allows [`frictionless_shm_types::MAX_PUBLISHERS`] publishers per service), and nothing
//! on the RT path.

use std::fs::File;
use std::io::{Read, Seek, Write};
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

use crate::config::Config;

/// Why the instance lock could not be taken.
#[derive(Debug, thiserror::Error)]
pub enum InstanceError {
    /// Another `frictiond` holds the lock.
    #[error(
        "another frictiond is running on service prefix {prefix:?} ({}; lock {}): stop it first",
        pid.map(|p| format!("PID {p}")).unwrap_or_else(|| "PID unknown".into()),
        path.display()
    )]
    Running {
        /// The service prefix.
        prefix: String,
        /// The first daemon's PID, if its lock file says.
        pid: Option<i32>,
        /// The lock file.
        path: PathBuf,
    },
    /// The lock file could not be created, locked or written.
    #[error("instance lock {}: {source}", path.display())]
    Io {
        /// The lock file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The iceoryx2 root path could not be resolved.
    #[error("resolving the iceoryx2 root path: {0}")]
    Root(#[from] frictionless_shm_types::ShmError),
}

/// The held lock; released when dropped or when the process exits.
#[derive(Debug)]
pub struct InstanceLock {
    _file: File,
    path: PathBuf,
}

/// FNV-1a 64 of `bytes` (file names stay short whatever the prefix; the prefix itself is written
/// into the file).
fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The lock file of `prefix` under `root`.
pub fn lock_path(root: &Path, prefix: &str) -> PathBuf {
    root.join(format!(
        "frictiond-{:016x}.lock",
        fnv1a64(prefix.as_bytes())
    ))
}

/// The lock file for `cfg`: under `[backend] root_path`, else under iceoryx2's default root.
pub fn lock_path_for(cfg: &Config) -> Result<PathBuf, InstanceError> {
    let root = match &cfg.root_path {
        Some(r) => r.clone(),
        None => {
            let ipc = crate::backend::shm::ipc_config(cfg);
            let c = ipc.iceoryx_config()?;
            PathBuf::from(c.global.root_path().to_string())
        }
    };
    Ok(lock_path(&root, &cfg.raw.backend.service_prefix))
}

impl InstanceLock {
    /// Takes the lock for `cfg`'s root path and service prefix (creating the root directory if
    /// needed) and writes this process's PID into it.
    pub fn acquire(cfg: &Config) -> Result<Self, InstanceError> {
        let path = lock_path_for(cfg)?;
        Self::acquire_at(&path, &cfg.raw.backend.service_prefix)
    }

    /// Takes the lock at `path` for `prefix`.
    pub fn acquire_at(path: &Path, prefix: &str) -> Result<Self, InstanceError> {
        let io = |source| InstanceError::Io {
            path: path.to_path_buf(),
            source,
        };
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(io)?;
        // SAFETY: flock on a descriptor we own; no memory is passed.
        let rc = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if rc != 0 {
            let err = std::io::Error::last_os_error();
            if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                let mut text = String::new();
                let _ = file.read_to_string(&mut text);
                let pid = text.lines().next().and_then(|l| l.trim().parse().ok());
                return Err(InstanceError::Running {
                    prefix: prefix.to_owned(),
                    pid,
                    path: path.to_path_buf(),
                });
            }
            return Err(io(err));
        }
        file.set_len(0).map_err(io)?;
        file.rewind().map_err(io)?;
        write!(file, "{}\n{prefix}\n", std::process::id()).map_err(io)?;
        file.flush().map_err(io)?;
        Ok(Self {
            _file: file,
            path: path.to_path_buf(),
        })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_on_the_same_prefix_is_refused_naming_the_holder() {
        let dir = std::env::temp_dir().join(format!("fld_instance_{}", std::process::id()));
        let p = lock_path(&dir, "robot/a");
        let first = InstanceLock::acquire_at(&p, "robot/a").unwrap();
        // flock locks belong to the open file description: a second open in this process conflicts
        // like a second process would.
        let e = InstanceLock::acquire_at(&p, "robot/a").unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("\"robot/a\""), "{msg}");
        assert!(
            msg.contains(&format!("PID {}", std::process::id())),
            "{msg}"
        );
        // Another prefix is another file.
        assert_ne!(lock_path(&dir, "robot/b"), p);
        let _other = InstanceLock::acquire_at(&lock_path(&dir, "robot/b"), "robot/b").unwrap();
        drop(first);
        // Released on drop: the file stays, the lock is free again.
        let _again = InstanceLock::acquire_at(&p, "robot/a").unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}

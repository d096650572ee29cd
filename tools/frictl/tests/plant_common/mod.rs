//! Shared helpers for the tests that run the virtual plant as a real process (`frictl sim serve
//! --backend shm`): a scratch directory with its own iceoryx2 root and service prefix, and the
//! plant child process with its stderr captured line by line. Used by `sim_serve_shm` and
//! `acquire_live`; not a fake of anything — the plant is the real binary.

#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use frictionless_shm_types::{IpcConfig, monotonic_ns};

/// A unique scratch directory (iceoryx2 root under `iox/`, outputs under `out/`) and service
/// prefix; removed on drop.
pub struct Scratch {
    /// The scratch directory.
    pub dir: PathBuf,
    /// The iceoryx2 service prefix, unique per test.
    pub prefix: String,
}

impl Scratch {
    /// Creates `$TMPDIR/<tag-based unique name>/iox`.
    pub fn new(tag: &str) -> Self {
        let prefix = format!(
            "fl_plant_{tag}_{}_{}",
            std::process::id(),
            monotonic_ns() % 1_000_000_000
        );
        let dir = std::env::temp_dir().join(&prefix);
        std::fs::create_dir_all(dir.join("iox")).unwrap();
        Self { dir, prefix }
    }

    /// The iceoryx2 root path.
    pub fn root(&self) -> PathBuf {
        self.dir.join("iox")
    }

    /// The output directory (created by the program that writes into it).
    pub fn out(&self) -> PathBuf {
        self.dir.join("out")
    }

    /// The IPC configuration a test client opens.
    pub fn config(&self) -> IpcConfig {
        IpcConfig::new(Some(&self.root()), &self.prefix)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A running `frictl sim serve --backend shm` (spawned and waited for "ready"); killed on drop if
/// still running.
pub struct Plant {
    child: Child,
    lines: mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Plant {
    /// Spawns the plant on the scratch's root and prefix with `extra` arguments.
    pub fn spawn(s: &Scratch, extra: &[&str]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_frictl"))
            .args(["sim", "serve", "--backend", "shm", "--prefix", &s.prefix])
            .arg("--root-path")
            .arg(s.root())
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn frictl sim serve");
        let stderr = child.stderr.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut p = Self {
            child,
            lines,
            seen: Vec::new(),
        };
        p.wait_line("ready", Duration::from_secs(60));
        p
    }

    /// Returns a stderr line containing `needle`, seen before or arriving within `timeout`.
    pub fn wait_line(&mut self, needle: &str, timeout: Duration) -> String {
        if let Some(l) = self.seen.iter().find(|l| l.contains(needle)) {
            return l.clone();
        }
        let end = Instant::now() + timeout;
        loop {
            let left = end.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) => {
                    self.seen.push(l.clone());
                    if l.contains(needle) {
                        return l;
                    }
                }
                Err(_) => panic!("no `{needle}` on stderr; got {:?}", self.seen),
            }
        }
    }

    /// Sends `sig` to the plant.
    pub fn signal(&self, sig: libc::c_int) {
        // SAFETY: sending a signal to our own child by pid.
        assert_eq!(
            unsafe { libc::kill(self.child.id() as libc::pid_t, sig) },
            0
        );
    }

    /// The exit status if the plant has exited, without waiting.
    pub fn try_exit(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().unwrap()
    }

    /// Waits up to `timeout` for the plant to exit.
    pub fn wait_exit(&mut self, timeout: Duration) -> ExitStatus {
        let end = Instant::now() + timeout;
        loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                return st;
            }
            assert!(Instant::now() < end, "plant did not exit; {:?}", self.seen);
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Sends SIGTERM, waits for the exit and returns (success, every stderr line after "ready").
    pub fn terminate(mut self) -> (bool, Vec<String>) {
        self.signal(libc::SIGTERM);
        let ok = self.wait_exit(Duration::from_secs(30)).success();
        let mut lines: Vec<String> = self
            .seen
            .drain(..)
            .skip_while(|l| !l.contains("ready"))
            .skip(1)
            .collect();
        lines.extend(self.lines.try_iter());
        (ok, lines)
    }
}

impl Drop for Plant {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

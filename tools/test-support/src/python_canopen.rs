//! The python-canopen side of the CiA 402 tests on vcan (`vcan_cia402_canopen_*`, run in the CAN
//! VM by `tests/canvm/run.sh`, which puts a CPython with python-canopen into the VM and names it
//! in `FRICTIONLESS_CANVM_PYTHON`): the interpreter, the scripts in `tests/canvm/`, the EDS file of
//! the emulated drive, and a Python process whose stdout lines are collected as they come.

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The repository root (by name: inside the CAN VM only the files the tests use are there).
pub fn repo_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .and_then(Path::parent)
        .expect("tools/test-support is two levels below the root")
}

/// The Python interpreter: `FRICTIONLESS_CANVM_PYTHON` (set inside the CAN VM), else `python3`.
pub fn python() -> PathBuf {
    std::env::var_os("FRICTIONLESS_CANVM_PYTHON").map_or_else(|| "python3".into(), PathBuf::from)
}

/// A script of `tests/canvm/`.
pub fn script(name: &str) -> PathBuf {
    repo_root().join("tests/canvm").join(name)
}

/// `config/cia402_frictionless.eds`, the EDS file of the emulated drive.
pub fn eds() -> PathBuf {
    repo_root().join("config/cia402_frictionless.eds")
}

/// A running Python script (`python -u script args…`): stdout lines collected by a thread,
/// stderr kept for failure messages, stdin open for commands. Killed on drop if still running.
pub struct PyProcess {
    child: Child,
    stdin: Option<ChildStdin>,
    lines: Arc<Mutex<Vec<String>>>,
    stderr: Arc<Mutex<String>>,
    readers: Vec<JoinHandle<()>>,
}

impl PyProcess {
    /// Starts `script` with `args`.
    pub fn start(script: &Path, args: &[&str]) -> Self {
        let mut child = Command::new(python())
            .arg("-u")
            .arg(script)
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("spawn {} {}: {e}", python().display(), script.display()));
        let lines = Arc::new(Mutex::new(Vec::new()));
        let stderr = Arc::new(Mutex::new(String::new()));
        let out = child.stdout.take().unwrap();
        let err = child.stderr.take().unwrap();
        let (l2, e2) = (lines.clone(), stderr.clone());
        let readers = vec![
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(out).lines() {
                    let Ok(line) = line else { break };
                    l2.lock().unwrap().push(line);
                }
            }),
            std::thread::spawn(move || {
                for line in std::io::BufReader::new(err).lines() {
                    let Ok(line) = line else { break };
                    let mut s = e2.lock().unwrap();
                    s.push_str(&line);
                    s.push('\n');
                }
            }),
        ];
        Self {
            stdin: child.stdin.take(),
            child,
            lines,
            stderr,
            readers,
        }
    }

    /// The stdout lines so far.
    pub fn lines(&self) -> Vec<String> {
        self.lines.lock().unwrap().clone()
    }

    /// Stdout and stderr so far, for failure messages.
    pub fn transcript(&self) -> String {
        format!(
            "stdout:\n{}\nstderr:\n{}",
            self.lines().join("\n"),
            self.stderr.lock().unwrap()
        )
    }

    /// Waits for a stdout line at index ≥ `from` satisfying `pred`; returns its index. Panics with
    /// the transcript after `timeout` or when the process exits first.
    pub fn wait_line(
        &mut self,
        from: usize,
        timeout: Duration,
        mut pred: impl FnMut(&str) -> bool,
    ) -> usize {
        let t0 = Instant::now();
        loop {
            if let Some(k) = self.lines().iter().skip(from).position(|l| pred(l)) {
                return from + k;
            }
            if let Ok(Some(st)) = self.child.try_wait() {
                std::thread::sleep(Duration::from_millis(50));
                if let Some(k) = self.lines().iter().skip(from).position(|l| pred(l)) {
                    return from + k;
                }
                panic!("the script exited ({st}) first:\n{}", self.transcript());
            }
            assert!(
                t0.elapsed() < timeout,
                "no matching line within {timeout:?}:\n{}",
                self.transcript()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Sends one command line to the script's stdin.
    pub fn send(&mut self, line: &str) {
        let stdin = self.stdin.as_mut().expect("stdin open");
        writeln!(stdin, "{line}").expect("write to the script's stdin");
        stdin.flush().unwrap();
    }

    /// Closes stdin and waits up to `timeout` for the exit; returns the exit status and all
    /// stdout lines.
    pub fn finish(mut self, timeout: Duration) -> (ExitStatus, Vec<String>) {
        drop(self.stdin.take());
        let t0 = Instant::now();
        let st = loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                break st;
            }
            assert!(
                t0.elapsed() < timeout,
                "the script did not exit within {timeout:?}:\n{}",
                self.transcript()
            );
            std::thread::sleep(Duration::from_millis(10));
        };
        for r in self.readers.drain(..) {
            let _ = r.join();
        }
        (st, self.lines())
    }
}

impl Drop for PyProcess {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

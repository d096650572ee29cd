//! The control client (`fl_control_*`) against a live `frictiond` process: values set through the
//! C entry points show in the daemon's answers, refusals carry the rule, the preloaded models
//! switch by name; without a daemon, or with one that does not answer, a call fails with a clear
//! message within its timeout. Once in-process through the rlib and once from C
//! (`tests/c/control.c` against the `.so` and the `.a`).
//!
//! The daemon is the `frictiond` binary Cargo built (`$FRICTIOND`, as `tests/run.sh` and
//! `python/ci.sh` set it, else `target/<profile>/frictiond` beside this test's `deps/`), run as a
//! child process: the C library is tested the way a C program uses it — through its own `.so` / `.a`
//! against a separately started daemon — and no crate gains a dependency on the daemon's (the other
//! choice, the daemon's e2e test depending on this crate, would put a C compiler and this library in
//! the daemon's test build). `cargo test -p frictionless-capi` does not build another package's
//! binary, so these tests are `#[ignore]`d there; `tests/run.sh` builds it and runs them.

use std::ffi::{CStr, CString};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use frictionless::{
    FL_CONTROL_KEY_COMPENSATION, FL_CONTROL_KEY_KFC, FL_CONTROL_KEY_MAX_CURR, FL_CONTROL_KEY_MODEL,
    FL_CONTROL_OK, FL_CONTROL_REFUSED, FL_OOD_FLAG, fl_control, fl_control_close, fl_control_get,
    fl_control_open, fl_control_set, fl_control_state, fl_last_error, fl_model_kind_name,
    fl_status,
};

use crate::support::{compile_c, crate_dir, run_ok, scratch};

/// Bound of every wait for the daemon (start, first answer, exit); never a timing assert.
const T: Duration = Duration::from_secs(30);

/// The `frictiond` binary: `$FRICTIOND`, else `target/<profile>/frictiond`; panics naming both when
/// neither exists.
fn frictiond() -> PathBuf {
    if let Some(p) = std::env::var_os("FRICTIOND") {
        let p = PathBuf::from(p);
        assert!(p.exists(), "FRICTIOND = {} does not exist", p.display());
        return p;
    }
    let exe = std::env::current_exe().expect("current_exe");
    let p = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>/")
        .join("frictiond");
    assert!(
        p.exists(),
        "{} not found and FRICTIOND not set: build it first (`cargo build -p frictiond`; \
         tests/run.sh does)",
        p.display()
    );
    p
}

/// The knee of the daemon's config: a CV with two preloaded alternates (`scv_b`, `cv_soft`).
const KNEE: &str = r#"
[loop]
period_us = 1000
status_every_ticks = 10
ready_after_ticks = 10

[safety]
stale_after_ticks = 20
on_stale = "zero"

[[joint]]
name = "plain"
index = 0
gear_ratio = 100.0
kt = 0.157
max_curr = 5.0
friction_model = "none"

[[joint]]
name = "knee"
index = 1
gear_ratio = -100.0
kt = 0.157
max_curr = 5.0
kfc = 0.85
max_output_friction = 6.0
friction_model = "cv"
kc = 8.1
ka = 50.84
kv = 5.55

[[joint.alternate]]
name = "scv_b"
friction_model = "scv"
kc = 1.0
ka = 40.0
kv = 3.0
ks = 2.0
vs = 0.1
alpha = 0.8

[[joint.alternate]]
name = "cv_soft"
friction_model = "cv"
kc = 4.0
ka = 20.0
kv = 2.0
"#;

/// A per-test iceoryx2 root path and service prefix, and a `frictiond` serving them; SIGKILLed on
/// drop if still alive.
struct Live {
    dir: PathBuf,
    prefix: String,
    child: Child,
}

impl Live {
    fn start(tag: &str) -> Self {
        let dir = scratch(tag);
        std::fs::create_dir_all(dir.join("iox")).unwrap();
        let prefix = format!("flcapi_{tag}_{}", std::process::id());
        let cfg = dir.join("frictiond.toml");
        std::fs::write(
            &cfg,
            format!(
                "[backend]\nkind = \"shm\"\nservice_prefix = \"{prefix}\"\nroot_path = \"{}\"\n{KNEE}",
                dir.join("iox").display()
            ),
        )
        .unwrap();
        let log = std::fs::File::create(dir.join("frictiond.log")).unwrap();
        let child = Command::new(frictiond())
            .arg("--config")
            .arg(&cfg)
            .env("RUST_LOG", "info")
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("spawn frictiond");
        Live { dir, prefix, child }
    }

    fn root(&self) -> PathBuf {
        self.dir.join("iox")
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("frictiond.log")).unwrap_or_default()
    }

    fn signal(&self, sig: libc::c_int) {
        // SAFETY: kill(2) on our own child's pid.
        assert_eq!(
            unsafe { libc::kill(self.child.id() as libc::pid_t, sig) },
            0
        );
    }

    /// SIGTERM, then the exit (bounded by [`T`]): whether it succeeded.
    fn stop(&mut self) -> bool {
        self.signal(libc::SIGTERM);
        let deadline = Instant::now() + T;
        loop {
            if let Some(st) = self.child.try_wait().unwrap() {
                return st.success();
            }
            assert!(
                Instant::now() < deadline,
                "frictiond did not exit:\n{}",
                self.log()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A handle on this thread (closed on drop).
struct Handle(*mut fl_control);

impl Handle {
    fn open(prefix: &str, root: &Path, timeout_ms: u32) -> Self {
        let prefix = CString::new(prefix).unwrap();
        let root = CString::new(root.to_str().unwrap()).unwrap();
        let mut c = std::ptr::null_mut();
        // SAFETY: NUL-terminated strings and a writable out pointer.
        let st = unsafe { fl_control_open(prefix.as_ptr(), root.as_ptr(), timeout_ms, &mut c) };
        assert_eq!(st, fl_status::Ok, "{}", last());
        Handle(c)
    }

    fn get(&self, joint: &str) -> (fl_status, fl_control_state) {
        let joint = CString::new(joint).unwrap();
        let mut s = std::mem::MaybeUninit::<fl_control_state>::zeroed();
        // SAFETY: a live handle of this thread, a NUL-terminated string, writable storage.
        let st = unsafe { fl_control_get(self.0, joint.as_ptr(), s.as_mut_ptr()) };
        // SAFETY: zero is a valid fl_control_state (numbers, bool false, NUL texts).
        (st, unsafe { s.assume_init() })
    }

    fn set(&self, joint: &str, key: &str, value: &str) -> (fl_status, fl_control_state) {
        let [joint, key, value] = [joint, key, value].map(|t| CString::new(t).unwrap());
        let mut s = std::mem::MaybeUninit::<fl_control_state>::zeroed();
        // SAFETY: as in `get`.
        let st = unsafe {
            fl_control_set(
                self.0,
                joint.as_ptr(),
                key.as_ptr(),
                value.as_ptr(),
                s.as_mut_ptr(),
            )
        };
        // SAFETY: as in `get`.
        (st, unsafe { s.assume_init() })
    }

    /// Gets `joint` until the daemon answers (it opens its control server after its RT thread is
    /// up), bounded by [`T`].
    fn wait_for(&self, live: &Live, joint: &str) -> fl_control_state {
        let deadline = Instant::now() + T;
        loop {
            let (st, s) = self.get(joint);
            if st == fl_status::Ok {
                return s;
            }
            assert_eq!(st, fl_status::Ipc, "{}", last());
            assert!(
                Instant::now() < deadline,
                "no control answer: {}\n{}",
                last(),
                live.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Handle {
    fn drop(&mut self) {
        // SAFETY: the handle was opened on this thread and is not used afterwards.
        assert_eq!(unsafe { fl_control_close(self.0) }, fl_status::Ok);
    }
}

fn last() -> String {
    // SAFETY: fl_last_error never returns NULL and the buffer is NUL-terminated.
    unsafe { CStr::from_ptr(fl_last_error()) }
        .to_string_lossy()
        .into_owned()
}

fn text(a: &[std::ffi::c_char]) -> String {
    // SAFETY: the library NUL-terminates every text of fl_control_state within its array.
    unsafe { CStr::from_ptr(a.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

fn models(s: &fl_control_state) -> Vec<String> {
    let mut v = Vec::new();
    let mut at = 0;
    while s.models[at] != 0 {
        let n = text(&s.models[at..]);
        at += n.len() + 1;
        v.push(n);
    }
    assert_eq!(v.len(), s.n_models as usize);
    v
}

fn kind(s: &fl_control_state) -> String {
    let p = fl_model_kind_name(s.model_kind);
    assert!(!p.is_null(), "kind code {}", s.model_kind);
    // SAFETY: a non-NULL result is a static NUL-terminated string.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

#[test]
#[ignore = "needs the frictiond binary (FRICTIOND or target/<profile>/frictiond; tests/run.sh builds it)"]
fn control_calls_on_a_live_frictiond_set_values_switch_models_and_name_refused_rules() {
    let mut live = Live::start("ctl_live");
    let c = Handle::open(&live.prefix, &live.root(), 2000);
    let g = c.wait_for(&live, "knee");
    assert_eq!(g.control_status, FL_CONTROL_OK);
    assert_eq!(
        (g.joint_index, g.kfc, g.max_output_friction_nm, g.max_curr_a),
        (1, 0.85, 6.0, 5.0)
    );
    assert!(g.compensation);
    assert_eq!((g.ood_mode, g.generation), (FL_OOD_FLAG, 0));
    assert_eq!((text(&g.model), kind(&g)), ("default".into(), "cv".into()));
    assert_eq!(models(&g), ["default", "scv_b", "cv_soft", "none"]);
    assert_eq!(g.set_since_ns, [0; 6], "every value is the file's");
    assert_eq!(text(&g.message), "ok");

    // Sets: each answer carries the value now in use and when it was set.
    let (st, s) = c.set("knee", "kfc", "0.3");
    assert_eq!(st, fl_status::Ok, "{}", last());
    assert_eq!(s.kfc, 0.3);
    assert!(s.set_since_ns[FL_CONTROL_KEY_KFC as usize] > 0);
    assert!(
        text(&s.message).contains("applied from the next tick"),
        "{}",
        text(&s.message)
    );
    let (st, s) = c.set("knee", "compensation", "off");
    assert_eq!(st, fl_status::Ok, "{}", last());
    assert!(!s.compensation && s.set_since_ns[FL_CONTROL_KEY_COMPENSATION as usize] > 0);
    let (st, s) = c.set("knee", "compensation", "on");
    assert_eq!(st, fl_status::Ok, "{}", last());
    assert!(s.compensation);
    for (name, want_kind) in [("scv_b", "scv"), ("none", "none"), ("cv_soft", "cv")] {
        let (st, s) = c.set("knee", "model", name);
        assert_eq!(st, fl_status::Ok, "model = {name}: {}", last());
        assert_eq!(
            (text(&s.model), kind(&s)),
            (name.to_owned(), want_kind.to_owned())
        );
        assert!(s.set_since_ns[FL_CONTROL_KEY_MODEL as usize] > 0);
    }
    let g = c.get("knee").1;
    assert_eq!(
        (g.kfc, g.compensation, text(&g.model)),
        (0.3, true, "cv_soft".into())
    );
    assert_eq!(
        g.set_since_ns[FL_CONTROL_KEY_MAX_CURR as usize], 0,
        "max_curr is the file's"
    );

    // Refusals: FL_STATUS_REFUSED, the daemon's code and its message naming the rule, in the
    // state and in fl_last_error; the values in use unchanged.
    for (joint, key, value, rule) in [
        ("knee", "kfc", "3", "must be in [0, 2]"),
        (
            "knee",
            "max_curr",
            "6",
            "must be <= the file's max_curr (5)",
        ),
        (
            "knee",
            "model",
            "lugre_x",
            "no such model of this joint (available: default, scv_b, cv_soft, none)",
        ),
        ("knee", "kp", "1", "not a runtime key"),
        ("hip", "kfc", "1", "no such joint"),
    ] {
        let (st, s) = c.set(joint, key, value);
        assert_eq!(st, fl_status::Refused, "{joint} {key}={value}");
        assert_eq!(
            s.control_status, FL_CONTROL_REFUSED,
            "{joint} {key}={value}"
        );
        assert!(
            text(&s.message).contains(rule),
            "{key}={value}: {}",
            text(&s.message)
        );
        assert!(
            last().contains("frictiond refused") && last().contains(rule),
            "{}",
            last()
        );
        if joint == "knee" {
            assert_eq!(
                (s.kfc, text(&s.model)),
                (0.3, "cv_soft".into()),
                "{key}={value}"
            );
        } else {
            assert_eq!(s.joint_index, u32::MAX);
        }
    }
    let (st, s) = c.get("hip");
    assert_eq!(
        (st, s.control_status),
        (fl_status::Refused, FL_CONTROL_REFUSED)
    );
    assert!(
        text(&s.message).contains("configured: plain, knee"),
        "{}",
        text(&s.message)
    );

    // A daemon that does not answer (stopped): the call ends at its timeout with a message.
    let short = Handle::open(&live.prefix, &live.root(), 300);
    live.signal(libc::SIGSTOP);
    let (st, _) = short.get("knee");
    let msg = last();
    live.signal(libc::SIGCONT);
    assert_eq!(st, fl_status::Ipc, "{msg}");
    assert!(msg.contains("no answer within 300 ms"), "{msg}");
    assert!(
        msg.contains("joint `knee`") && msg.contains("/control"),
        "{msg}"
    );
    // ... and answers again once it runs.
    assert_eq!(short.wait_for(&live, "knee").kfc, 0.3);
    drop(short);

    drop(c);
    assert!(live.stop(), "{}", live.log());
    let log = live.log();
    assert!(log.contains("control: joint `knee`: `kfc` = 0.3"), "{log}");
    assert!(
        log.contains("must be in [0, 2]"),
        "refusals are logged: {log}"
    );
}

#[test]
fn control_calls_without_a_daemon_fail_at_once_naming_the_service() {
    let dir = scratch("ctl_none");
    let prefix = format!("flcapi_none_{}", std::process::id());
    // A long timeout: the failure must come from the missing server, not the wait.
    let c = Handle::open(&prefix, &dir, 600_000);
    let (st, _) = c.get("knee");
    let msg = last();
    assert_eq!(st, fl_status::Ipc, "{msg}");
    assert!(msg.contains(&format!("{prefix}/control")), "{msg}");
    // "no server", not "no answer within": it did not wait.
    assert!(msg.contains("no server (is frictiond running"), "{msg}");
    let (st, _) = c.set("knee", "kfc", "0.5");
    assert_eq!(st, fl_status::Ipc, "{}", last());
}

/// One line of `control.c`: the fields before ` | `, the message, the last error.
fn c_lines(stdout: &[u8]) -> Vec<(Vec<String>, String, String)> {
    let text = String::from_utf8_lossy(stdout);
    let mut lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.pop(), Some("done"), "{text}");
    lines
        .iter()
        .map(|l| {
            let mut parts = l.splitn(3, " | ");
            let fields = parts
                .next()
                .unwrap()
                .split(' ')
                .map(str::to_owned)
                .collect();
            let message = parts.next().expect("message").to_owned();
            let error = parts.next().expect("last error").to_owned();
            (fields, message, error)
        })
        .collect()
}

#[test]
#[ignore = "needs the frictiond binary (FRICTIOND or target/<profile>/frictiond; tests/run.sh builds it)"]
fn c_program_drives_a_live_frictiond_through_the_so_and_the_a() {
    let mut live = Live::start("ctl_c");
    let dir = live.dir.clone();
    let shared = dir.join("control_shared");
    let static_ = dir.join("control_static");
    let source = crate_dir().join("tests/c/control.c");
    compile_c(&source, &shared, false, &[]);
    compile_c(&source, &static_, true, &[]);
    // The daemon is up once the in-process client has an answer.
    let c = Handle::open(&live.prefix, &live.root(), 2000);
    c.wait_for(&live, "knee");
    let ops = [
        "get:knee",
        "set:knee:kfc:0.4",
        "set:knee:compensation:off",
        "set:knee:model:scv_b",
        "set:knee:kfc:3",
        "set:knee:model:nope",
        "get:hip",
        "set:knee:compensation:on",
    ];
    let mut outputs = Vec::new();
    for (generation, exe) in [&shared, &static_].into_iter().enumerate() {
        if generation > 0 {
            // A reload restores the file's values for the next program.
            live.signal(libc::SIGHUP);
            let deadline = Instant::now() + T;
            while c.get("knee").1.generation != generation as u64 {
                assert!(Instant::now() < deadline, "no reload:\n{}", live.log());
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        let out = run_ok(
            Command::new(exe)
                .arg(&live.prefix)
                .arg(live.root())
                .arg("2000")
                .args(ops),
        );
        let lines = c_lines(&out.stdout);
        assert_eq!(lines.len(), ops.len());
        // Fields: status, control status, index, kfc, max_output_friction, max_curr, compensation,
        // ood, model, kind, n_models, models, since kfc, since compensation, since model.
        let (f, msg, _) = &lines[0];
        assert_eq!(
            &f[..12],
            [
                "FL_STATUS_OK",
                "0",
                "1",
                "0.84999999999999998",
                "6",
                "5",
                "on",
                "flag",
                "default",
                "cv",
                "4",
                "default,scv_b,cv_soft,none",
            ]
            .map(str::to_owned),
            "{f:?}"
        );
        assert_eq!(msg, "ok");
        let (f, _, _) = &lines[1];
        assert_eq!(
            (f[0].as_str(), f[3].as_str()),
            ("FL_STATUS_OK", "0.40000000000000002")
        );
        assert_ne!(f[12], "0", "kfc set at a time");
        let (f, _, _) = &lines[2];
        assert_eq!((f[0].as_str(), f[6].as_str()), ("FL_STATUS_OK", "off"));
        assert_ne!(f[13], "0");
        let (f, _, _) = &lines[3];
        assert_eq!(
            (f[0].as_str(), f[8].as_str(), f[9].as_str()),
            ("FL_STATUS_OK", "scv_b", "scv")
        );
        assert_ne!(f[14], "0");
        for (k, rule) in [
            (4, "must be in [0, 2]"),
            (
                5,
                "no such model of this joint (available: default, scv_b, cv_soft, none)",
            ),
            (6, "no such joint"),
        ] {
            let (f, msg, err) = &lines[k];
            assert_eq!(
                (f[0].as_str(), f[1].as_str()),
                ("FL_STATUS_REFUSED", "1"),
                "{}",
                ops[k]
            );
            assert!(msg.contains(rule), "{}: {msg}", ops[k]);
            assert!(
                err.contains("frictiond refused") && err.contains(rule),
                "{}: {err}",
                ops[k]
            );
        }
        // The refused sets changed nothing; the unknown joint's answer holds no values.
        assert_eq!(
            (lines[4].0[3].as_str(), lines[5].0[8].as_str()),
            ("0.40000000000000002", "scv_b")
        );
        assert_eq!(lines[6].0[2], u32::MAX.to_string());
        assert_eq!(lines[7].0[6], "on");
        outputs.push(lines);
    }
    drop(c);
    assert!(live.stop(), "{}", live.log());

    // Without the daemon: every call fails at once, the message naming the service.
    let out = run_ok(
        Command::new(&shared)
            .arg(&live.prefix)
            .arg(live.root())
            .arg("600000")
            .args(["get:knee", "set:knee:kfc:0.5"]),
    );
    for (f, _, err) in c_lines(&out.stdout) {
        assert_eq!(f[0], "FL_STATUS_IPC", "{err}");
        assert!(
            err.contains("/control") && err.contains("is frictiond running"),
            "{err}"
        );
    }
    // The .so and .a programs saw the same daemon answers (set times aside).
    let strip = |l: &Vec<(Vec<String>, String, String)>| -> Vec<Vec<String>> {
        l.iter().map(|(f, _, _)| f[..12].to_vec()).collect()
    };
    assert_eq!(strip(&outputs[0]), strip(&outputs[1]));
}

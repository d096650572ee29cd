//! Runtime control of a live `frictiond` over `<prefix>/control` (iceoryx2 request–response), in
//! lockstep against the test process as the plant: a set is answered before the next tick, which
//! computes the law with the new value (references in `daemon_support`, not the daemon's code);
//! refusals name the rule; a reload restores the file's values; `[control] writes = false`
//! refuses every set; `model = NAME` switches among the joint's preloaded models at a tick
//! boundary.

use std::time::Duration;

use crate::daemon_support::*;
use frictionless::model::ModelKind;
use frictionless_shm_types::Ipc;
use frictionless_shm_types::control::{
    CONTROL_KEYS, CONTROL_OK, CONTROL_REFUSED, CONTROL_WRITES_DISABLED, ControlClient,
    ControlRequest, ControlResponse,
};

fn lockstep(extra: &str) -> String {
    THREE_JOINTS.replace(
        "[loop]\nperiod_us = 1000\nstatus_every_ticks = 10\nready_after_ticks = 10\n",
        &format!(
            "{extra}[loop]\nperiod_us = 1000\nstatus_every_ticks = 10\nready_after_ticks = 1\n\
             trigger = \"lockstep\"\nlockstep_wait_request = true\nlockstep_timeout_ms = 3600000\n"
        ),
    )
}

/// Opens a control client and waits (bounded by [`T`]) until the daemon answers a get of `joint`:
/// the daemon opens its server just after its RT thread is up.
pub(crate) fn connect(env: &TestEnv, joint: &str) -> (Ipc, ControlClient) {
    let ipc = Ipc::open(&env.ipc, "ctl").unwrap();
    let c = ipc.control_client().unwrap();
    let deadline = std::time::Instant::now() + T;
    let req = ControlRequest::get(joint).unwrap();
    while c.call(&req, Duration::from_millis(200)).is_err() {
        assert!(std::time::Instant::now() < deadline, "no control answer");
    }
    (ipc, c)
}

pub(crate) fn set(c: &ControlClient, joint: &str, key: &str, value: &str) -> ControlResponse {
    c.call(&ControlRequest::set(joint, key, value).unwrap(), T)
        .expect("control answer")
}

fn get(c: &ControlClient, joint: &str) -> ControlResponse {
    c.call(&ControlRequest::get(joint).unwrap(), T)
        .expect("control answer")
}

/// One lockstep tick with torque 2 Nm and ṡ = 0.3 rad/s on every joint: the knee's current.
/// SIGHUP, then `joint`'s get once it reports parameter generation `generation` (the reload done).
fn reload(d: &Daemon, c: &ControlClient, joint: &str, generation: u64) -> ControlResponse {
    d.signal(libc::SIGHUP);
    let deadline = std::time::Instant::now() + T;
    loop {
        let g = get(c, joint);
        if g.generation == generation {
            return g;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "no reload to generation {generation}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

fn knee_current(plant: &mut Plant) -> f64 {
    let (js, rq) = inputs([2.0; 3], [0.3; 3]);
    let k = plant.publish_state(&js);
    plant.publish_request(&rq, k);
    plant.command_for(k, T).expect("command").i_ref_a[1]
}

/// The knee (`knee_cv`) law of [`THREE_JOINTS`] at τ 2 Nm, ṡ 0.3 with `kfc`, compensation on or
/// off and `max_curr`.
fn knee_ref(kfc: f64, on: bool, max_curr: f64) -> f64 {
    let f = if on {
        cv_ref(8.1, 50.84, 5.55, 0.3)
    } else {
        0.0
    };
    current_ref(2.0, f, 0.3, 0.05, 6.0, kfc, 0.157, -100.0, max_curr)
}

#[test]
fn sets_take_effect_on_the_next_tick_refusals_name_the_rule_and_reload_restores() {
    let env = TestEnv::new("ctl");
    let cfg = env.write_config(&lockstep(""));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (_ipc, c) = connect(&env, "knee_cv");

    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref(0.85, true, 5.0)), "{i}");
    let g = get(&c, "knee_cv");
    assert_eq!(g.status, CONTROL_OK, "{}", g.message());
    assert_eq!(
        (g.kfc, g.max_curr_a, g.compensation, g.generation),
        (0.85, 5.0, 1, 0)
    );
    assert_eq!(
        g.set_since_ns,
        [0; CONTROL_KEYS.len()],
        "all values are the file's"
    );

    for (key, value, want) in [
        ("kfc", "0.3", knee_ref(0.3, true, 5.0)),
        ("compensation", "off", knee_ref(0.3, false, 5.0)),
        ("compensation", "on", knee_ref(0.3, true, 5.0)),
        ("max_curr", "0.5", knee_ref(0.3, true, 0.5)),
    ] {
        let r = set(&c, "knee_cv", key, value);
        assert_eq!(r.status, CONTROL_OK, "{key}={value}: {}", r.message());
        let i = knee_current(&mut plant);
        assert!(close(i, want), "{key}={value}: {i} vs {want}");
    }
    // DaemonStatus counts the applied changes (published every 10 ticks).
    let mut applied = 0;
    for _ in 0..50 {
        let i = knee_current(&mut plant);
        assert!(close(i, knee_ref(0.3, true, 0.5)), "{i}");
        if let Some(s) = plant.status.latest().unwrap() {
            applied = s.control_applied;
            assert_eq!(s.control_dropped, 0);
            if applied >= 4 {
                break;
            }
        }
    }
    assert_eq!(applied, 4, "DaemonStatus::control_applied");
    let g = get(&c, "knee_cv");
    assert_eq!((g.kfc, g.max_curr_a, g.compensation), (0.3, 0.5, 1));
    assert!(
        g.set_since_ns[0] > 0 && g.set_since_ns[2] > 0,
        "{:?}",
        g.set_since_ns
    );
    assert_eq!(
        g.set_since_ns[1], 0,
        "max_output_friction is still the file's"
    );

    for (joint, key, value, rule) in [
        ("knee_cv", "kfc", "3", "must be in [0, 2]"),
        (
            "knee_cv",
            "max_curr",
            "6",
            "must be <= the file's max_curr (5)",
        ),
        ("knee_cv", "kp", "1", "not a runtime key"),
        ("hip", "kfc", "1", "no such joint"),
    ] {
        let r = set(&c, joint, key, value);
        assert_eq!(r.status, CONTROL_REFUSED, "{key}={value}");
        assert!(r.message().contains(rule), "{key}={value}: {}", r.message());
    }
    // Refused values changed nothing.
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref(0.3, true, 0.5)), "{i}");

    // A reload restores the file's values: once get reports the new generation, the next tick
    // runs the file's law again.
    let g = reload(&d, &c, "knee_cv", 1);
    assert_eq!((g.kfc, g.max_curr_a, g.compensation), (0.85, 5.0, 1));
    assert_eq!(g.set_since_ns, [0; CONTROL_KEYS.len()]);
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref(0.85, true, 5.0)), "{i}");

    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    assert!(
        log.contains("control: joint `knee_cv`: `kfc` = 0.3"),
        "{log}"
    );
    assert!(
        log.contains("must be in [0, 2]"),
        "refusals are logged: {log}"
    );
}

/// Two alternates of the knee (after its own CV keys): an SCV and a softer CV.
pub(crate) const KNEE_ALTERNATES: &str = "kv = 5.55\n\n\
[[joint.alternate]]\nname = \"scv_b\"\nfriction_model = \"scv\"\n\
kc = 1.0\nka = 40.0\nkv = 3.0\nks = 2.0\nvs = 0.1\nalpha = 0.8\n\n\
[[joint.alternate]]\nname = \"cv_soft\"\nfriction_model = \"cv\"\nkc = 4.0\nka = 20.0\nkv = 2.0\n";

/// [`lockstep`] with [`KNEE_ALTERNATES`].
pub(crate) fn lockstep_with_alternates(extra: &str) -> String {
    lockstep(extra).replacen("kv = 5.55\n", KNEE_ALTERNATES, 1)
}

/// The knee law at τ 2 Nm, ṡ 0.3 with the file's gains and friction estimate `f` [Nm].
fn knee_ref_f(f: f64) -> f64 {
    current_ref(2.0, f, 0.3, 0.05, 6.0, 0.85, 0.157, -100.0, 5.0)
}

#[test]
fn model_sets_switch_among_the_preloaded_models_at_the_next_tick_and_reload_restores() {
    let env = TestEnv::new("ctlmodel");
    let cfg = env.write_config(&lockstep_with_alternates(""));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (_ipc, c) = connect(&env, "knee_cv");
    let own = cv_ref(8.1, 50.84, 5.55, 0.3);
    let scv_b = scv_ref(1.0, 40.0, 3.0, 2.0, 0.1, 0.8, 0.3);
    let cv_soft = cv_ref(4.0, 20.0, 2.0, 0.3);
    assert!(scv_b != own && cv_soft != own && scv_b != cv_soft);

    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref_f(own)), "{i}");
    let g = get(&c, "knee_cv");
    assert_eq!((g.model(), g.model_since_tick), ("default", 0));
    assert_eq!(
        g.models().collect::<Vec<_>>(),
        ["default", "scv_b", "cv_soft", "none"]
    );
    assert_eq!(g.model_kind, u32::from(ModelKind::Cv.code()));

    let mut ticks = 1;
    for (name, f, kind) in [
        ("scv_b", scv_b, ModelKind::Scv),
        ("none", 0.0, ModelKind::None),
        ("cv_soft", cv_soft, ModelKind::Cv),
        ("default", own, ModelKind::Cv),
        ("scv_b", scv_b, ModelKind::Scv),
    ] {
        let r = set(&c, "knee_cv", "model", name);
        assert_eq!(r.status, CONTROL_OK, "model={name}: {}", r.message());
        // The very next tick runs the law with the new model's estimate, and every later one.
        for _ in 0..3 {
            let i = knee_current(&mut plant);
            assert!(
                close(i, knee_ref_f(f)),
                "model={name}: {i} vs {}",
                knee_ref_f(f)
            );
            ticks += 1;
        }
        let g = get(&c, "knee_cv");
        assert_eq!(g.model(), name);
        assert_eq!(g.model_kind, u32::from(kind.code()), "{name}");
        assert!(g.set_since_ns[5] > 0, "{:?}", g.set_since_ns);
        assert!(
            g.model_since_tick > 0 && g.model_since_tick <= ticks - 3,
            "{name}: since tick {} of {ticks}",
            g.model_since_tick
        );
        // The other joints keep their own model.
        assert_eq!(get(&c, "ankle_scv").model(), "default");
    }

    // An unknown name is refused with the list; nothing changes.
    let r = set(&c, "knee_cv", "model", "lugre_x");
    assert_eq!(r.status, CONTROL_REFUSED);
    assert!(
        r.message()
            .contains("no such model of this joint (available: default, scv_b, cv_soft, none)"),
        "{}",
        r.message()
    );
    let r = set(&c, "plain", "model", "scv_b");
    assert_eq!(r.status, CONTROL_REFUSED);
    assert!(
        r.message().contains("(available: default, none)"),
        "{}",
        r.message()
    );
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref_f(scv_b)), "{i}");

    // A reload reloads the alternates from the file and runs the joint's own model again.
    let g = reload(&d, &c, "knee_cv", 1);
    assert_eq!(
        (g.model(), g.model_since_tick, g.set_since_ns[5]),
        ("default", 0, 0)
    );
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref_f(own)), "{i}");
    let r = set(&c, "knee_cv", "model", "cv_soft");
    assert_eq!(r.status, CONTROL_OK, "{}", r.message());
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref_f(cv_soft)), "{i}");

    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
    assert!(
        log.contains("control: joint `knee_cv`: `model` = scv_b"),
        "{log}"
    );
}

#[test]
fn writes_off_refuses_every_set_and_still_answers_gets() {
    let env = TestEnv::new("ctlro");
    let cfg = env.write_config(&lockstep("[control]\nwrites = false\n\n"));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (_ipc, c) = connect(&env, "knee_cv");
    let r = set(&c, "knee_cv", "kfc", "0.3");
    assert_eq!(r.status, CONTROL_WRITES_DISABLED, "{}", r.message());
    assert!(
        r.message().contains("[control] writes = false"),
        "{}",
        r.message()
    );
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref(0.85, true, 5.0)), "{i}");
    assert_eq!(get(&c, "knee_cv").kfc, 0.85);
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
}

#[test]
#[ignore = "needs the frictl binary beside frictiond: bash tests/run.sh"]
fn frictl_ctl_sets_and_gets_a_live_daemon() {
    use std::process::Command;
    let frictl = frictl_bin();
    let env = TestEnv::new("ctlcli");
    let cfg = env.write_config(&lockstep(""));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (_ipc, _c) = connect(&env, "knee_cv");
    let root = env.ipc.root_path.clone().unwrap();
    let ctl = |args: &[&str]| {
        let out = Command::new(&frictl)
            .arg("ctl")
            .args(args)
            .args(["--prefix", &env.ipc.service_prefix, "--root-path"])
            .arg(&root)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stdout).into_owned(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (ok, out, err) = ctl(&["set", "knee_cv", "kfc=0.3", "compensation=off"]);
    assert!(ok, "{out}{err}");
    assert!(
        out.contains("`kfc` = 0.3") && out.contains("`compensation` = off"),
        "{out}"
    );
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref(0.3, false, 5.0)), "{i}");
    let (ok, out, err) = ctl(&["get", "knee_cv", "--json"]);
    assert!(ok, "{out}{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect(&out);
    assert_eq!(v["kfc"], 0.3);
    assert_eq!(v["compensation"], "off");
    assert_eq!(v["max_curr"], 5.0);
    assert!(v["set_since_ns"]["kfc"].as_u64().unwrap() > 0, "{v}");
    assert!(v["set_since_ns"]["max_curr"].is_null(), "{v}");
    // A refusal: non-zero exit, the rule on stderr.
    let (ok, _, err) = ctl(&["set", "knee_cv", "kfc=3"]);
    assert!(!ok);
    assert!(err.contains("must be in [0, 2]"), "{err}");
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
}

#[test]
#[ignore = "needs root (to run frictl as nobody) and the frictl binary beside frictiond: bash tests/run.sh"]
fn another_user_is_refused_with_a_clear_message_while_the_owner_sets() {
    use std::process::Command;
    // SAFETY: geteuid has no preconditions.
    assert_eq!(
        unsafe { libc::geteuid() },
        0,
        "this test runs frictl as nobody: run it as root"
    );
    let frictl = frictl_bin();
    let env = TestEnv::new("ctluser");
    let cfg = env.write_config(&lockstep(""));
    let mut d = Daemon::start(&cfg, &[]);
    let mut plant = Plant::open(&env.ipc, "plant");
    plant.wait_for_daemon(T);
    let (_ipc, c) = connect(&env, "knee_cv");
    let root = env.ipc.root_path.clone().unwrap();
    let ctl = |as_nobody: bool, args: &[&str]| {
        let mut cmd = if as_nobody {
            let mut c = Command::new("setpriv");
            c.args(["--reuid=nobody", "--regid=nogroup", "--clear-groups", "--"])
                .arg(&frictl);
            c
        } else {
            Command::new(&frictl)
        };
        let out = cmd
            .arg("ctl")
            .args(args)
            .args(["--prefix", &env.ipc.service_prefix, "--root-path"])
            .arg(&root)
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (ok, err) = ctl(true, &["set", "knee_cv", "kfc=0.3"]);
    assert!(!ok, "nobody's set must fail: {err}");
    assert!(
        err.contains("permission denied") && err.contains("only frictiond's user"),
        "{err}"
    );
    let (ok, err) = ctl(true, &["get", "knee_cv"]);
    assert!(!ok && err.contains("permission denied"), "{err}");
    // Nothing changed; the owner's set goes through.
    assert_eq!(get(&c, "knee_cv").kfc, 0.85);
    let (ok, err) = ctl(false, &["set", "knee_cv", "kfc=0.3"]);
    assert!(ok, "{err}");
    let i = knee_current(&mut plant);
    assert!(close(i, knee_ref(0.3, true, 5.0)), "{i}");
    d.signal(libc::SIGTERM);
    let (st, log) = d.wait_exit(T);
    assert!(st.success(), "{log}");
}

//! `frictl sim serve --backend shm` as a real process over real iceoryx2, talking to a minimal
//! client in the test process: lockstep sign conventions, SimTruth/JointStates pairing,
//! determinism, real-time rate and command timeout, disturbances, SIGTERM; the coupled leg
//! (`--preset leg`) on the same payloads.
//!
//! Every test uses its own iceoryx2 root directory and prefix and removes the directory at the end.

use std::time::{Duration, Instant};

use frictionless_shm_types::sim::{SimDisturbance, SimTruth};
use frictionless_shm_types::{Inbox, Ipc, JointStates, MotorCurrentCommand, Outbox, monotonic_ns};
use frictionless_sim::params::load_table;
use frictionless_sim::{LegParams, LegPlant, PlantParams};

use crate::plant_common;
use plant_common::{Plant, Scratch};

/// The test's side: a controller that answers states with commands (inbox before outbox, as the
/// lockstep plant requires).
struct Client {
    states: Inbox<JointStates>,
    truth: Inbox<SimTruth>,
    commands: Outbox<MotorCurrentCommand>,
    disturbance: Outbox<SimDisturbance>,
    _ipc: Ipc,
    cmd_seq: u64,
}

impl Client {
    fn open(s: &Scratch) -> Self {
        let ipc = Ipc::open(&s.config(), "test_client").unwrap();
        let states = ipc.joint_states().unwrap().inbox().unwrap();
        let truth = ipc.sim_truth().unwrap().inbox().unwrap();
        let disturbance = ipc.sim_disturbance().unwrap().outbox().unwrap();
        let commands = ipc.motor_current_command().unwrap().outbox().unwrap();
        Self {
            states,
            truth,
            commands,
            disturbance,
            _ipc: ipc,
            cmd_seq: 0,
        }
    }

    /// Waits for the state with `seq` (panics on a gap or timeout).
    fn state(&self, seq: u64) -> JointStates {
        let end = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(s) = self.states.latest().unwrap() {
                assert_eq!(s.seq, seq, "lockstep states arrive one by one");
                return s;
            }
            assert!(Instant::now() < end, "no state {seq}");
            let _ = self.states.wait(Duration::from_millis(20));
        }
    }

    /// The newest truth (waits until one with `seq` is there).
    fn truth(&self, seq: u64) -> SimTruth {
        let end = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some(t) = self.truth.latest().unwrap() {
                assert_eq!(t.seq, seq, "truth seq equals the state seq");
                return t;
            }
            assert!(Instant::now() < end, "no truth {seq}");
            let _ = self.truth.wait(Duration::from_millis(20));
        }
    }

    fn command(&mut self, state: &JointStates, i_ref_a: &[f64]) {
        self.cmd_seq += 1;
        let mut c = MotorCurrentCommand::zeroed();
        c.seq = self.cmd_seq;
        c.stamp_ns = monotonic_ns();
        c.state_seq = state.seq;
        c.state_stamp_ns = state.stamp_ns;
        c.n_joints = i_ref_a.len() as u32;
        for (j, &i) in i_ref_a.iter().enumerate() {
            c.valid_mask |= 1 << j;
            c.i_ref_a[j] = i;
        }
        self.commands.publish(&c).unwrap();
    }

    fn disturb(&self, tau_ext_nm: &[f64]) {
        let mut d = SimDisturbance::zeroed();
        d.n_joints = tau_ext_nm.len() as u32;
        d.stamp_ns = monotonic_ns();
        d.tau_ext_nm[..tau_ext_nm.len()].copy_from_slice(tau_ext_nm);
        self.disturbance.publish(&d).unwrap();
    }
}

/// Runs `ticks` lockstep ticks; `current(k)` and `tau_ext(k)` give the per-joint inputs answering
/// state `k` (1-based). Returns every (state, truth) pair, states 1..=ticks+1.
fn lockstep_run(
    tag: &str,
    seed: u64,
    ticks: u64,
    current: impl Fn(u64) -> Vec<f64>,
    tau_ext: impl Fn(u64) -> Option<Vec<f64>>,
) -> Vec<(JointStates, SimTruth)> {
    lockstep_run_of("knee,ankle_roll", tag, seed, ticks, current, tau_ext)
}

/// [`lockstep_run`] of the given `--preset` value.
fn lockstep_run_of(
    presets: &str,
    tag: &str,
    seed: u64,
    ticks: u64,
    current: impl Fn(u64) -> Vec<f64>,
    tau_ext: impl Fn(u64) -> Option<Vec<f64>>,
) -> Vec<(JointStates, SimTruth)> {
    let s = Scratch::new(tag);
    let mut plant = Plant::spawn(
        &s,
        &[
            "--preset",
            presets,
            "--lockstep",
            "--seed",
            &seed.to_string(),
            "--duration-s",
            &format!("{}", ticks as f64 * 1e-3),
        ],
    );
    let mut client = Client::open(&s);
    let mut out = Vec::new();
    for k in 1..=ticks + 1 {
        let st = client.state(k);
        let tr = client.truth(k);
        out.push((st, tr));
        if k <= ticks {
            if let Some(d) = tau_ext(k) {
                client.disturb(&d);
            }
            client.command(&st, &current(k));
        }
    }
    let status = plant.wait_exit(Duration::from_secs(30));
    assert!(status.success(), "plant exit: {status:?}");
    let summary = plant.wait_line("ticks", Duration::from_secs(5));
    assert!(summary.contains(&format!("{ticks} ticks")), "{summary}");
    out
}

fn gear_ratio_signed(preset: &str) -> f64 {
    PlantParams::from_table(&load_table(preset, None, &[]).unwrap())
        .unwrap()
        .gear_ratio_signed
}

#[test]
fn lockstep_constant_current_moves_each_joint_in_the_sign_of_r_times_i() {
    let r = [gear_ratio_signed("knee"), gear_ratio_signed("ankle_roll")];
    // Well above friction + gravity on both joints, of opposite signs.
    let i = [3.0, -2.0];
    let run = lockstep_run("sign", 1, 100, |_| i.to_vec(), |_| None);
    let (first, _) = run[0];
    let (last, last_truth) = run[run.len() - 1];
    assert_eq!(first.n_joints, 2);
    for j in 0..2 {
        let ds = last.s_rad[j] - first.s_rad[j];
        let expected = (r[j] * i[j]).signum();
        assert!(
            ds * expected > 0.01,
            "joint {j}: Δs = {ds} rad, expected sign {expected} (r = {}, i = {})",
            r[j],
            i[j]
        );
        // The reported velocity agrees in sign with the motion, and the current is applied.
        assert!(last.sdot_rad_s[j] * expected > 0.0, "joint {j} velocity");
        assert_eq!(last_truth.i_applied_a[j], i[j]);
        // Measured current tracks the reference (noise ≤ a few tens of mA).
        assert!((last.current_a[j] - i[j]).abs() < 0.1, "joint {j} current");
        // Motor angle θ = r_signed·φ moves with r_signed·s.
        let dtheta = last.theta_motor_rad[j] - first.theta_motor_rad[j];
        assert!(
            dtheta * r[j] * ds > 0.0,
            "joint {j}: θ and r·s move together"
        );
    }
    for (k, (st, tr)) in run.iter().enumerate() {
        assert_eq!(st.seq, k as u64 + 1);
        assert_eq!(tr.seq, st.seq, "SimTruth seq matches JointStates seq");
        assert_eq!(tr.stamp_ns, st.stamp_ns, "published together");
        assert!(
            (tr.sim_time_s - k as f64 * 1e-3).abs() < 1e-9,
            "sim time = (seq − 1) ms"
        );
        assert!(
            st.temperature_c[0].is_nan(),
            "the knee has no temperature sensor"
        );
        assert!(
            st.temperature_c[1].is_finite(),
            "the ankle roll has a PT100"
        );
        assert!(st.tau_meas_nm[0].is_nan(), "no joint torque sensor");
    }
}

#[test]
fn lockstep_is_deterministic_for_a_seed_and_commands() {
    let cur = |k: u64| {
        let t = k as f64 * 1e-3;
        vec![
            2.0 * (std::f64::consts::TAU * 3.0 * t).sin(),
            -1.5 * (std::f64::consts::TAU * 5.0 * t).cos(),
        ]
    };
    let a = lockstep_run("det_a", 7, 300, cur, |_| None);
    let b = lockstep_run("det_b", 7, 300, cur, |_| None);
    let c = lockstep_run("det_c", 8, 300, cur, |_| None);
    assert_eq!(a.len(), b.len());
    let fields = |s: &JointStates, j: usize| {
        [
            s.s_rad[j],
            s.sdot_rad_s[j],
            s.theta_motor_rad[j],
            s.omega_motor_rad_s[j],
            s.current_a[j],
            s.temperature_c[j],
        ]
    };
    let mut differs_with_other_seed = false;
    for k in 0..a.len() {
        for j in 0..2 {
            let (fa, fb, fc) = (fields(&a[k].0, j), fields(&b[k].0, j), fields(&c[k].0, j));
            for n in 0..fa.len() {
                assert!(
                    fa[n].to_bits() == fb[n].to_bits(),
                    "state {} joint {j} field {n}: {} vs {}",
                    k + 1,
                    fa[n],
                    fb[n]
                );
            }
            differs_with_other_seed |= fa.iter().zip(&fc).any(|(x, y)| x.to_bits() != y.to_bits());
        }
        assert_eq!(a[k].1.tau_f_true_nm[0], b[k].1.tau_f_true_nm[0]);
    }
    assert!(
        differs_with_other_seed,
        "another seed gives other noise: the comparison can fail"
    );
    // The motion is not trivial.
    assert!((a[a.len() - 1].0.s_rad[0] - a[0].0.s_rad[0]).abs() > 1e-3);
}

#[test]
fn lockstep_disturbance_moves_the_joint_and_is_echoed_in_the_truth() {
    // No current (valid, 0 A), ankle roll only; +8 Nm beats its ≈ 4 Nm stiction.
    let ticks = 300;
    let tau = 8.0;
    let pushed = lockstep_run(
        "dist",
        2,
        ticks,
        |_| vec![0.0, 0.0],
        |k| (k == 1).then(|| vec![0.0, tau]),
    );
    let still = lockstep_run("nodist", 2, ticks, |_| vec![0.0, 0.0], |_| None);
    let ds = |run: &[(JointStates, SimTruth)]| run[run.len() - 1].0.s_rad[1] - run[0].0.s_rad[1];
    assert!(
        ds(&pushed) > 0.01,
        "+{tau} Nm moves s up: Δs = {}",
        ds(&pushed)
    );
    assert!(
        ds(&still).abs() < 1e-3,
        "no push, no motion: {}",
        ds(&still)
    );
    // Held until replaced: every step after the first command carries it.
    for (st, tr) in &pushed[1..] {
        assert_eq!(tr.tau_ext_nm[1], tau, "state {}", st.seq);
        assert_eq!(tr.tau_ext_nm[0], 0.0);
    }
}

#[test]
fn real_time_plant_publishes_on_its_own_and_commands_time_out_to_zero() {
    let s = Scratch::new("rt");
    let mut plant = Plant::spawn(
        &s,
        &["--preset", "knee,ankle_roll", "--command-timeout-ms", "20"],
    );
    let mut client = Client::open(&s);
    // Count distinct states over 1 s of wall time.
    let t0 = Instant::now();
    let (mut first, mut last) = (None, 0u64);
    while t0.elapsed() < Duration::from_secs(1) {
        if let Some(st) = client.states.latest().unwrap() {
            first.get_or_insert(st.seq);
            last = st.seq;
        }
        let _ = client.states.wait(Duration::from_millis(5));
    }
    let published = last - first.expect("states arrive");
    // The rate is a measurement, not an assertion (this machine is noisy): printed for the log.
    println!("real-time plant: {published} new states in 1 s of wall time (nominal 1000)");
    assert!(
        published > 0,
        "the real-time plant keeps publishing on its own"
    );

    // Command 1.5 A on the ankle roll for 300 ms; the truth shows it applied.
    let t1 = Instant::now();
    let mut seen_applied = false;
    while t1.elapsed() < Duration::from_millis(300) {
        if let Some(st) = client.states.latest().unwrap() {
            client.command(&st, &[0.0, 1.5]);
        }
        if let Some(tr) = client.truth.latest().unwrap() {
            seen_applied |= tr.i_applied_a[1] == 1.5;
        }
        let _ = client.states.wait(Duration::from_millis(5));
    }
    assert!(seen_applied, "the commanded current is applied");
    // Stop commanding: after the 20 ms timeout (wait 300 ms) the plant applies 0 A.
    std::thread::sleep(Duration::from_millis(300));
    let _ = client.truth.latest().unwrap();
    let end = Instant::now() + Duration::from_secs(5);
    let tr = loop {
        if let Some(tr) = client.truth.latest().unwrap() {
            break tr;
        }
        assert!(Instant::now() < end, "truth keeps coming");
        let _ = client.truth.wait(Duration::from_millis(5));
    };
    assert_eq!(tr.i_applied_a[1], 0.0, "0 A after the command timeout");
    assert_eq!(tr.i_applied_a[0], 0.0);

    plant.signal(libc::SIGINT);
    let st = plant.wait_exit(Duration::from_secs(10));
    assert!(st.success(), "SIGINT → clean exit: {st:?}");
    let summary = plant.wait_line("ticks", Duration::from_secs(5));
    assert!(summary.contains("commands received"), "{summary}");
}

#[test]
fn sigterm_stops_a_real_time_and_a_waiting_lockstep_plant_with_exit_0() {
    let s = Scratch::new("term_rt");
    let mut plant = Plant::spawn(&s, &["--preset", "ankle_roll"]);
    std::thread::sleep(Duration::from_millis(200));
    plant.signal(libc::SIGTERM);
    let st = plant.wait_exit(Duration::from_secs(10));
    assert!(st.success(), "real time: {st:?}");
    let summary = plant.wait_line("ticks", Duration::from_secs(5));
    assert!(
        !summary.starts_with("frictl sim serve: 0 ticks"),
        "{summary}"
    );

    // Lockstep with nobody connected: waiting for peers, SIGTERM still ends it cleanly.
    let s = Scratch::new("term_ls");
    let mut plant = Plant::spawn(&s, &["--preset", "ankle_roll", "--lockstep"]);
    std::thread::sleep(Duration::from_millis(200));
    plant.signal(libc::SIGTERM);
    let st = plant.wait_exit(Duration::from_secs(10));
    assert!(st.success(), "lockstep: {st:?}");
}

#[test]
fn lockstep_timeout_without_answers_holds_then_zeroes_and_keeps_going() {
    // A client that answers only state 1 with 1 A, then goes silent: the plant times out every
    // tick (100 ms here: long enough for the client to open and read state 1 on a loaded machine),
    // holds the command for 3 simulated ms, then applies 0 A.
    let s = Scratch::new("ls_to");
    let mut plant = Plant::spawn(
        &s,
        &[
            "--preset",
            "ankle_roll",
            "--lockstep",
            "--lockstep-timeout-ms",
            "100",
            "--command-timeout-ms",
            "3",
            "--duration-s",
            "0.008",
        ],
    );
    let mut client = Client::open(&s);
    let st = client.state(1);
    client.command(&st, &[1.0]);
    let mut applied = Vec::new();
    let end = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(tr) = client.truth.latest().unwrap()
            && tr.seq >= 2
        {
            applied.push((tr.seq, tr.i_applied_a[0]));
        }
        if let Some(st) = plant.try_exit() {
            break st;
        }
        assert!(Instant::now() < end, "plant advances without answers");
        let _ = client.truth.wait(Duration::from_millis(2));
    };
    assert!(status.success(), "{status:?}");
    let warning = plant.wait_line("warning", Duration::from_secs(5));
    assert!(warning.contains("lockstep"), "{warning}");
    let summary = plant.wait_line("ticks", Duration::from_secs(5));
    assert!(summary.contains("8 ticks"), "{summary}");
    // Truth k reports the current applied during tick k − 2 (0-based): the answered tick and two
    // held ones carry 1 A, later ticks 0 A.
    assert!(applied.iter().any(|&(_, i)| i == 1.0), "{applied:?}");
    assert!(applied.iter().any(|&(_, i)| i == 0.0), "{applied:?}");
    for &(seq, i) in &applied {
        let tick = seq - 2;
        let expected = if tick < 3 { 1.0 } else { 0.0 };
        assert_eq!(i, expected, "tick {tick} (truth {seq}): {applied:?}");
    }
}

/// Leg test inputs answering state `k`: each joint its own sine around a constant current.
fn leg_current(k: u64) -> Vec<f64> {
    let t = k as f64 * 1e-3;
    let amp = [1.5, -1.0, 0.6, 2.0, -0.5, 0.4];
    let bias = [2.0, 1.0, 0.0, -1.0, 0.3, 0.0];
    (0..6)
        .map(|j| bias[j] + amp[j] * (std::f64::consts::TAU * (1.0 + j as f64) * t).sin())
        .collect()
}

#[test]
fn lockstep_leg_serves_six_coupled_joints_equal_to_the_leg_plant() {
    let ticks = 400;
    let tau_ext = [0.0, 0.0, 0.0, 0.0, 0.0, 1.5];
    let run = lockstep_run_of("leg", "leg", 4, ticks, leg_current, |k| {
        (k == 1).then(|| tau_ext.to_vec())
    });
    // The same leg in this process, stepped with the same inputs.
    let mut leg = LegPlant::new(LegParams::preset().unwrap(), 4).unwrap();
    let names: Vec<String> = leg.joint_names().map(str::to_owned).collect();
    let mut moved = [0.0f64; 6];
    for (k, (st, tr)) in run.iter().enumerate() {
        assert_eq!(st.n_joints, 6, "six joints on the payload");
        assert_eq!(tr.n_joints, 6);
        assert_eq!(tr.seq, st.seq);
        for (j, smp) in leg.samples().iter().enumerate() {
            let m = smp.meas;
            let pairs = [
                ("s_rad", st.s_rad[j], m.s_rad),
                ("theta_motor_rad", st.theta_motor_rad[j], m.theta_motor_rad),
                ("current_a", st.current_a[j], m.i_meas_a),
                ("tau_f_true_nm", tr.tau_f_true_nm[j], smp.truth.tau_f_nm),
                (
                    "sdot_true_rad_s",
                    tr.sdot_true_rad_s[j],
                    smp.truth.state.s_dot_rad_s,
                ),
            ];
            for (what, served, own) in pairs {
                assert!(
                    served.to_bits() == own.to_bits(),
                    "state {} joint {} {what}: served {served} vs leg {own}",
                    k + 1,
                    names[j]
                );
            }
            assert_eq!(
                st.temperature_c[j].is_nan(),
                m.temperature_c.is_nan(),
                "joint {}",
                names[j]
            );
            moved[j] = moved[j].max((st.s_rad[j] - run[0].0.s_rad[j]).abs());
        }
        if (k as u64) < ticks {
            let i = leg_current(k as u64 + 1);
            let i_max: Vec<f64> = leg.params().joints.iter().map(|p| p.i_max_a).collect();
            let applied: Vec<f64> = i.iter().zip(&i_max).map(|(i, m)| i.clamp(-m, *m)).collect();
            if let Some((_, next)) = run.get(k + 1) {
                assert_eq!(&next.i_applied_a[..6], &applied[..], "state {}", k + 2);
            }
            leg.step(&applied, &tau_ext).unwrap();
        }
    }
    // Every joint moves: each got its own command.
    for (j, d) in moved.iter().enumerate() {
        assert!(*d > 1e-3, "joint {} moved only {d} rad", names[j]);
    }
}

#[test]
fn the_leg_preset_is_not_mixed_with_single_joints() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(["sim", "serve", "--preset", "knee,leg", "--lockstep"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("knee,leg") && err.contains("cannot be combined"),
        "{err}"
    );
}

#[test]
fn an_initial_pose_beyond_three_turns_is_refused_before_serving() {
    // Before: 100 rad was accepted and the plant served from it.
    for pose in ["100", "nan"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_frictl"))
            .args(["sim", "serve", "--preset", "knee", "--lockstep"])
            .arg(format!("--initial-pose-rad={pose}"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{pose} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("--initial-pose-rad entry 1") && err.contains("three turns"),
            "{pose}: {err}"
        );
    }
}

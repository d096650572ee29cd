//! Coupled-robot speed: one simulated second (1000 samples × 20 physics steps, each with one drive per
//! joint and one articulated-body solve) under current sines on every joint, for
//! - the built-in ergoCub left leg (`config/presets/leg.toml`, six joints; target ≥ 50× real time,
//!   i.e. ≤ 20 ms per iteration),
//! - the whole ergoCub URDF without its hands: every movable joint but the 24 finger joints a drive
//!   (33 joints, each the `ankle_roll` preset scaled to its link; target ≥ 10×, ≤ 100 ms per
//!   iteration), and, printed only, the whole URDF with the fingers' joints (57),
//!
//! plus one ABA solve of the leg on its own. Real-time factor = 1 s / reported time; printed directly
//! at the end as well, by the wall clock and by the thread's CPU time, with the ABA's CPU time per solve.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frictionless_dynamics::{Robot, Workspace};
use frictionless_sim::leg::{ERGOCUB_URDF, ERGOCUB_URDF_PATH, LegParams, LegPlant};
use nalgebra::DMatrix;

/// Every joint's current: its holding current plus a sine of `amp`·i_max at 0.7 + 0.2·k Hz.
fn currents(leg: &LegPlant, hold: &[f64], amp: f64, t: f64, i: &mut [f64]) {
    for (k, p) in leg.params().joints.iter().enumerate() {
        i[k] =
            hold[k] + amp * p.i_max_a * (std::f64::consts::TAU * (0.7 + 0.2 * k as f64) * t).sin();
    }
}

/// The leg's current sines relative to i_max.
const LEG_AMP: f64 = 0.5;
/// The whole robot's: its joints have no limits, and half of i_max whirls the arms and the head
/// until the explicit step no longer follows.
const ROBOT_AMP: f64 = 0.1;

/// Buffers of one robot's inputs, allocated once.
struct Inputs {
    /// Sine amplitude relative to i_max.
    amp: f64,
    hold: Vec<f64>,
    i: Vec<f64>,
    ext: Vec<f64>,
}

impl Inputs {
    fn new(leg: &LegPlant, amp: f64) -> Self {
        let n = leg.dof();
        Self {
            amp,
            hold: (0..n).map(|k| leg.state(k).i_a).collect(),
            i: vec![0.0; n],
            ext: vec![0.0; n],
        }
    }
}

fn one_simulated_second(leg: &mut LegPlant, inp: &mut Inputs, t0: &mut f64) -> f64 {
    let mut acc = 0.0;
    let k = leg.dof() / 2;
    for _ in 0..1000 {
        currents(leg, &inp.hold, inp.amp, *t0, &mut inp.i);
        *t0 += 1e-3;
        let out = leg.step(&inp.i, &inp.ext).expect("robot steps");
        acc += out[k].truth.tau_f_nm;
    }
    acc
}

/// The ergoCub's movable joints without the fingers' (names with `index`, `middle`, `ring`,
/// `pinkie` or `thumb`).
fn ergocub_joints_without_hands() -> Vec<String> {
    let robot = Robot::from_urdf_str(ERGOCUB_URDF, ERGOCUB_URDF_PATH).expect("ergoCub URDF");
    let fingers = ["index", "middle", "ring", "pinkie", "thumb"];
    robot
        .joint_names()
        .filter(|n| !fingers.iter().any(|f| n.contains(f)))
        .map(str::to_owned)
        .collect()
}

/// Link-side inertia at which a drive keeps its preset unchanged [kg·m²].
const J_REF_KGM2: f64 = 0.01;

/// A robot of `joints` of the ergoCub URDF (the rest locked at 0), each driven by the `ankle_roll`
/// preset scaled to its link: with J = 1/(M(0)⁻¹)_jj the inertia the joint's explicit step sees and
/// ρ = min(1, J / [`J_REF_KGM2`]), every torque constant, stiffness, damping, friction force and the
/// motor inertia are multiplied by ρ (the preset's drive on a finger would be unstable at 20 kHz:
/// its damping·dt exceeds twice the finger's inertia).
fn ergocub_params(joints: &[String]) -> LegParams {
    let list: Vec<String> = joints.iter().map(|j| format!("\"{j}\"")).collect();
    let mut text = format!(
        "[leg]\nurdf = \"ergocub\"\njoints = [{}]\n",
        list.join(", ")
    );
    for j in joints {
        text +=
            &format!("[joint.{j}]\npreset = \"ankle_roll\"\n[joint.{j}.plant]\njoint = \"{j}\"\n");
    }
    let mut params = LegParams::from_toml_str(&text, "<bench robot>", &[]).expect("robot table");
    let robot = params.nominal_robot().expect("ergoCub model");
    let n = robot.dof();
    let mut ws = Workspace::new(&robot);
    let mut m = DMatrix::zeros(n, n);
    robot
        .mass_matrix(&mut ws, &vec![0.0; n], &mut m)
        .expect("mass matrix");
    let m_inv = m.try_inverse().expect("M(0) invertible");
    for p in &mut params.joints {
        let j = robot.joint_index(&p.joint).expect("joint of the model");
        let rho = (1.0 / m_inv[(j, j)] / J_REF_KGM2).min(1.0);
        for x in [
            &mut p.kt_nm_per_a,
            &mut p.j_motor_kgm2,
            &mut p.k1_nm_per_rad,
            &mut p.k3_nm_per_rad3,
            &mut p.d_t_nms_per_rad,
            &mut p.f_cm_nm,
            &mut p.sigma2m_nms_per_rad,
            &mut p.f_c0_nm,
            &mut p.delta_f_c_nm,
            &mut p.f_s0_nm,
            &mut p.sigma0_nm_per_rad,
            &mut p.sigma1_nms_per_rad,
            &mut p.sigma2j_nms_per_rad,
        ] {
            *x *= rho;
        }
    }
    params
}

/// One ABA solve's thread CPU time [µs], over 10⁶ solves, plain and from tracked (sin q, cos q).
fn aba_cpu_us(robot: &Robot) -> (f64, f64) {
    let n = robot.dof();
    let mut ws = Workspace::new(robot);
    let q: Vec<f64> = (0..n).map(|j| 0.3 - 0.1 * j as f64).collect();
    let sc: Vec<(f64, f64)> = q.iter().map(|x| x.sin_cos()).collect();
    let qd: Vec<f64> = (0..n).map(|j| 0.5 - 0.2 * j as f64).collect();
    let tau: Vec<f64> = (0..n).map(|j| 10.0 - 2.0 * j as f64).collect();
    let mut qdd = vec![0.0; n];
    let calls = 1_000_000;
    let cpu0 = thread_cpu_s().unwrap_or(0.0);
    for _ in 0..calls {
        robot
            .aba(
                &mut ws,
                black_box(&q),
                black_box(&qd),
                black_box(&tau),
                &mut qdd,
            )
            .unwrap();
        black_box(&qdd);
    }
    let cpu1 = thread_cpu_s().unwrap_or(0.0);
    for _ in 0..calls {
        robot
            .aba_with_armature_sin_cos(
                &mut ws,
                black_box(&q),
                black_box(&sc),
                black_box(&qd),
                black_box(&tau),
                None,
                &mut qdd,
            )
            .unwrap();
        black_box(&qdd);
    }
    let cpu2 = thread_cpu_s().unwrap_or(0.0);
    let us = |a: f64, b: f64| (b - a) / calls as f64 * 1e6;
    (us(cpu0, cpu1), us(cpu1, cpu2))
}

/// The real-time factor over `seconds` simulated seconds: by the wall clock, and by the thread's own
/// CPU time (Linux schedstat), which a loaded machine does not inflate.
fn report(name: &str, params: LegParams, amp: f64, seconds: usize, target: f64) {
    let mut leg = LegPlant::new(params, 2).expect("valid robot");
    let mut inp = Inputs::new(&leg, amp);
    let mut t = 0.0;
    let cpu0 = thread_cpu_s();
    let start = std::time::Instant::now();
    for _ in 0..seconds {
        black_box(one_simulated_second(&mut leg, &mut inp, &mut t));
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = thread_cpu_s().zip(cpu0).map(|(b, a)| b - a);
    let s = seconds as f64;
    println!(
        "{name} ({} joints): {seconds} simulated s in {wall:.3} s of wall time: {:.1}× real time at 20 kHz (target ≥ {target}×)",
        leg.dof(),
        s / wall
    );
    if let Some(cpu) = cpu {
        println!(
            "{name}: {cpu:.3} s of thread CPU time: {:.1}× real time on one core",
            s / cpu
        );
    }
}

fn bench(c: &mut Criterion) {
    let params = LegParams::preset().expect("built-in leg preset");
    let mut leg = LegPlant::new(params, 1).expect("valid leg");
    assert_eq!(leg.dof(), 6);
    let mut inp = Inputs::new(&leg, LEG_AMP);
    let mut t = 0.0;
    c.bench_function("leg_1s_ergocub_left_leg", |b| {
        b.iter(|| black_box(one_simulated_second(&mut leg, &mut inp, &mut t)))
    });

    let robot = leg.robot().clone();
    let mut ws = Workspace::new(&robot);
    let q = [0.3, 0.2, -0.1, -0.8, 0.1, 0.05];
    let qd = [0.5, -0.3, 0.2, 1.0, -0.4, 0.6];
    let tau = [10.0, 5.0, 1.0, 3.0, 0.5, 0.2];
    let mut qdd = [0.0; 6];
    c.bench_function("aba_ergocub_left_leg_6dof", |b| {
        b.iter(|| {
            robot
                .aba(
                    &mut ws,
                    black_box(&q),
                    black_box(&qd),
                    black_box(&tau),
                    &mut qdd,
                )
                .unwrap();
            black_box(&qdd);
        })
    });

    let joints = ergocub_joints_without_hands();
    let mut whole = LegPlant::new(ergocub_params(&joints), 1).expect("valid robot");
    let mut inp = Inputs::new(&whole, ROBOT_AMP);
    let mut t = 0.0;
    let mut group = c.benchmark_group("ergocub_without_hands");
    group.sample_size(10);
    group.bench_function("robot_1s_ergocub_without_hands", |b| {
        b.iter(|| black_box(one_simulated_second(&mut whole, &mut inp, &mut t)))
    });
    group.finish();

    report(
        "leg",
        LegParams::preset().expect("preset"),
        LEG_AMP,
        10,
        50.0,
    );
    let (plain, sin_cos) = aba_cpu_us(&robot);
    println!(
        "aba, leg: {plain:.3} µs, from tracked sin/cos {sin_cos:.3} µs of thread CPU time per solve"
    );
    report(
        "ergoCub without hands",
        ergocub_params(&joints),
        ROBOT_AMP,
        3,
        10.0,
    );
    whole_with_hands();
}

/// Every movable joint of the ergoCub a drive, the fingers' included: reports where it stops.
fn whole_with_hands() {
    let robot = Robot::from_urdf_str(ERGOCUB_URDF, ERGOCUB_URDF_PATH).expect("ergoCub URDF");
    let all: Vec<String> = robot.joint_names().map(str::to_owned).collect();
    let mut leg = LegPlant::new(ergocub_params(&all), 1).expect("valid robot");
    let mut inp = Inputs::new(&leg, ROBOT_AMP);
    for k in 0..1000 {
        currents(&leg, &inp.hold, inp.amp, k as f64 * 1e-3, &mut inp.i);
        match leg.step(&inp.i, &inp.ext) {
            Ok(out) if out.iter().all(|s| s.truth.state.s_rad.is_finite()) => {}
            Ok(_) => {
                println!(
                    "whole ergoCub ({} joints): not finite after {k} ms",
                    leg.dof()
                );
                return;
            }
            Err(e) => {
                println!(
                    "whole ergoCub ({} joints): fails after {k} ms: {e}",
                    leg.dof()
                );
                return;
            }
        }
    }
    report("whole ergoCub", ergocub_params(&all), ROBOT_AMP, 1, 10.0);
}

/// CPU time of the calling thread [s] from /proc/thread-self/schedstat (None elsewhere).
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

criterion_group!(benches, bench);
criterion_main!(benches);

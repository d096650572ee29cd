//! Coupled-leg speed: one simulated second (1000 samples × 20 physics steps, each with the six drives
//! and one articulated-body solve) of the built-in ergoCub left leg (`config/presets/leg.toml`) under
//! current sines on every joint. Real-time factor = 1 s / reported time (target ≥ 50×, i.e. ≤ 20 ms
//! per iteration); printed directly at the end as well. Also one ABA solve on its own.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use frictionless_dynamics::Workspace;
use frictionless_sim::leg::{LegParams, LegPlant};

fn currents(leg: &LegPlant, hold: &[f64], t: f64) -> [f64; 6] {
    let mut i = [0.0; 6];
    for (k, p) in leg.params().joints.iter().enumerate() {
        i[k] =
            hold[k] + 0.5 * p.i_max_a * (std::f64::consts::TAU * (0.7 + 0.2 * k as f64) * t).sin();
    }
    i
}

fn one_simulated_second(leg: &mut LegPlant, hold: &[f64], t0: &mut f64) -> f64 {
    let mut acc = 0.0;
    let ext = [0.0; 6];
    for _ in 0..1000 {
        let i = currents(leg, hold, *t0);
        *t0 += 1e-3;
        let out = leg.step(&i, &ext).expect("leg steps");
        acc += out[3].truth.tau_f_nm;
    }
    acc
}

fn bench(c: &mut Criterion) {
    let params = LegParams::preset().expect("built-in leg preset");
    let mut leg = LegPlant::new(params, 1).expect("valid leg");
    assert_eq!(leg.dof(), 6);
    let hold: Vec<f64> = (0..6).map(|k| leg.state(k).i_a).collect();
    let mut t = 0.0;
    c.bench_function("leg_1s_ergocub_left_leg", |b| {
        b.iter(|| black_box(one_simulated_second(&mut leg, &hold, &mut t)))
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

    // The real-time factor, measured directly over 10 simulated seconds: by the wall clock, and by
    // the thread's own CPU time (Linux schedstat), which a loaded machine does not inflate.
    let mut leg = LegPlant::new(LegParams::preset().expect("preset"), 2).expect("valid leg");
    let mut t = 0.0;
    let cpu0 = thread_cpu_s();
    let start = std::time::Instant::now();
    for _ in 0..10 {
        black_box(one_simulated_second(&mut leg, &hold, &mut t));
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = thread_cpu_s().zip(cpu0).map(|(b, a)| b - a);
    println!(
        "leg: 10 simulated s in {wall:.3} s of wall time: {:.1}× real time at 20 kHz (target ≥ 50×)",
        10.0 / wall
    );
    if let Some(cpu) = cpu {
        println!(
            "leg: {cpu:.3} s of thread CPU time: {:.1}× real time on one core",
            10.0 / cpu
        );
    }
}

/// CPU time of the calling thread [s] from /proc/thread-self/schedstat (None elsewhere).
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

criterion_group!(benches, bench);
criterion_main!(benches);

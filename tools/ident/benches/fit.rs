//! Criterion bench: LM fit of CV and SCV on 10⁶ synthetic samples (the ≤ 1 s budget of `frictl fit`),
//! and the label pipeline's zero-phase Butterworth + RTS smoother on 10⁶ samples.

use criterion::{Criterion, criterion_group, criterion_main};
use frictionless::filter::Butterworth;
use frictionless::friction::{CvParams, ScvParams, StaticFriction, paper};
use frictionless_ident::fit::{FitOptions, fit};
use frictionless_ident::kalman::{KalmanConfig, smooth};

fn data<M: StaticFriction>(m: &M, n: usize) -> (Vec<f64>, Vec<f64>) {
    // Deterministic pseudo-random velocities and noise (LCG), no RNG crate needed in the bench.
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut u = || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let v: Vec<f64> = (0..n).map(|_| (u() * 2.0 - 1.0) * 2.0).collect();
    let t = v
        .iter()
        .map(|&v| m.torque_nm(v) + (u() - 0.5) * 0.3)
        .collect();
    (v, t)
}

fn bench(c: &mut Criterion) {
    let n = 1_000_000;
    let mut g = c.benchmark_group("fit_1e6");
    g.sample_size(10);
    let (v, t) = data(&paper::CV_ANKLE_ROLL, n);
    g.bench_function("lm_cv", |b| {
        b.iter(|| fit::<CvParams>(&v, &t, &FitOptions::default()).unwrap())
    });
    let (v, t) = data(&paper::SCV_ANKLE_ROLL, n);
    g.bench_function("lm_scv", |b| {
        b.iter(|| fit::<ScvParams>(&v, &t, &FitOptions::default()).unwrap())
    });
    let bw = Butterworth::lowpass(5, 100.0, 1000.0).unwrap();
    g.bench_function("sosfiltfilt_5th", |b| b.iter(|| bw.filtfilt(&t).unwrap()));
    let s: Vec<f64> = (0..n).map(|k| (k as f64 * 1e-3).sin()).collect();
    g.bench_function("kalman_rts", |b| {
        b.iter(|| smooth(&KalmanConfig::knee(), 1e-3, &s).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

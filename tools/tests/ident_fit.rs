//! `frictl::ident::fit` recovers known static-friction parameters from synthetic data with noise.

use frictionless::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction, paper};
use frictl::ident::fit::{FitOptions, Loss, Method, fit, select, sliding_quadrant_mask};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Velocities uniform in ±[0.03, v_max] and τ = model(v) + N(0, σ).
fn data<M: StaticFriction>(
    m: &M,
    n: usize,
    v_max: f64,
    sigma: f64,
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    let v: Vec<f64> = (0..n)
        .map(|_| {
            let mag = rng.random_range(0.03..v_max);
            if rng.random_bool(0.5) { mag } else { -mag }
        })
        .collect();
    let t = v
        .iter()
        .map(|&x| m.torque_nm(x) + noise.sample(&mut rng))
        .collect();
    (v, t)
}

fn close(name: &str, got: f64, want: f64, rel: f64) {
    assert!(
        (got - want).abs() <= rel * want.abs(),
        "{name}: got {got}, want {want} (±{:.0} %)",
        rel * 100.0
    );
}

#[test]
fn lm_recovers_cv_knee() {
    let truth = paper::CV_KNEE;
    let (v, t) = data(&truth, 100_000, 3.0, 0.5, 1);
    let r = fit::<CvParams>(&v, &t, &FitOptions::default()).unwrap();
    close("kc", r.model.kc, truth.kc, 0.02);
    close("kv", r.model.kv, truth.kv, 0.02);
    close("ka", r.model.ka, truth.ka, 0.15);
    // The residual is the noise.
    close("rmse", r.rmse_nm, 0.5, 0.02);
}

#[test]
fn lm_recovers_scv_ankle_roll() {
    let truth = paper::SCV_ANKLE_ROLL;
    let (v, t) = data(&truth, 200_000, 2.0, 0.02, 2);
    let r = fit::<ScvParams>(&v, &t, &FitOptions::default()).unwrap();
    // The least-squares optimum is at least as good as the truth on the same noisy data.
    let (rmse_truth, _) = frictl::ident::fit::errors(&truth, &v, &t);
    assert!(
        r.rmse_nm <= rmse_truth * (1.0 + 1e-9),
        "{} > {rmse_truth}",
        r.rmse_nm
    );
    let m = r.model;
    println!("fitted {m:?}, rmse {}", r.rmse_nm);
    close("kc", m.kc, truth.kc, 0.1);
    close("kv", m.kv, truth.kv, 0.05);
    close("ks", m.ks, truth.ks, 0.1);
    close("vs", m.vs, truth.vs, 0.15);
    close("alpha", m.alpha, truth.alpha, 0.15);
    close("ka", m.ka, truth.ka, 0.15);
    close("rmse", r.rmse_nm, 0.02, 0.02);
}

#[test]
fn lm_recovers_scv_code_form() {
    let truth = ScvCodeParams {
        fc: 4.0,
        fs: 9.0,
        fv: 5.0,
        vs: 0.3,
    };
    let (v, t) = data(&truth, 100_000, 3.0, 0.5, 3);
    let r = fit::<ScvCodeParams>(&v, &t, &FitOptions::default()).unwrap();
    close("fc", r.model.fc, truth.fc, 0.03);
    close("fs", r.model.fs, truth.fs, 0.03);
    close("fv", r.model.fv, truth.fv, 0.03);
    close("vs", r.model.vs, truth.vs, 0.05);
}

#[test]
fn adam_reaches_the_least_squares_optimum_on_cv() {
    let truth = paper::CV_ANKLE_ROLL;
    let (v, t) = data(&truth, 20_000, 2.0, 0.1, 4);
    let lm = fit::<CvParams>(&v, &t, &FitOptions::default()).unwrap();
    let opts = FitOptions {
        method: Method::Adam,
        adam_loss: Loss::Mse,
        ..FitOptions::default()
    };
    let ad = fit::<CvParams>(&v, &t, &opts).unwrap();
    println!(
        "lm {:?} {} / adam {:?} {}",
        lm.model, lm.rmse_nm, ad.model, ad.rmse_nm
    );
    assert!(
        ad.rmse_nm >= lm.rmse_nm * (1.0 - 1e-9),
        "LM is the least-squares optimum"
    );
    close("adam rmse", ad.rmse_nm, lm.rmse_nm, 0.02);
    close("adam kc", ad.model.kc, truth.kc, 0.1);
}

#[test]
fn sliding_quadrant_fit_ignores_stick_and_wrong_quadrant_samples() {
    // Sliding samples follow the truth; add stick samples (|v| < 0.03) and 2nd/4th-quadrant
    // samples with large torques that would bias an unmasked fit.
    let truth = paper::CV_KNEE;
    let (mut v, mut t) = data(&truth, 20_000, 3.0, 0.2, 5);
    for k in 0..5000 {
        let s = if k % 2 == 0 { 1.0 } else { -1.0 };
        v.push(0.01 * s);
        t.push(-20.0 * s);
        v.push(0.5 * s);
        t.push(-15.0 * s);
    }
    let mask = sliding_quadrant_mask(&v, &t, 0.03);
    assert_eq!(mask.iter().filter(|m| **m).count(), 20_000);
    let r = fit::<CvParams>(
        &select(&v, &mask),
        &select(&t, &mask),
        &FitOptions::default(),
    )
    .unwrap();
    close("kc", r.model.kc, truth.kc, 0.03);
    let unmasked = fit::<CvParams>(&v, &t, &FitOptions::default()).unwrap();
    assert!((unmasked.model.kc - truth.kc).abs() > 0.1 * truth.kc);
}

//! `frictionless_ident::fit` recovers known static-friction parameters from synthetic data with noise.

use frictionless::friction::{CvParams, ScvCodeParams, ScvParams, StaticFriction, paper};
use frictionless_ident::fit::{
    FitBounds, FitOptions, Loss, Method, fit, select, sliding_quadrant_mask,
};
use frictionless_ident::scv_fit::{ScvFitInput, fit_scv_guarded, scv_of_cv};
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
    let (rmse_truth, _) = frictionless_ident::fit::errors(&truth, &v, &t);
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

/// A pure-sign Coulomb label τ = kc·sign(v) + kv·v + noise, with velocities log-uniform in
/// ±[10 mrad/s, 2 rad/s]: the least-squares optimum is at ka → ∞ (tanh(ka·v) → sign(v)).
fn pure_sign_data(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 0.05).unwrap();
    let v: Vec<f64> = (0..n)
        .map(|_| {
            let mag = 10f64.powf(rng.random_range(-2.0..0.3));
            if rng.random_bool(0.5) { mag } else { -mag }
        })
        .collect();
    let t = v
        .iter()
        .map(|&x| 1.6 * x.signum() + 0.3 * x + noise.sample(&mut rng))
        .collect();
    (v, t)
}

#[test]
fn cv_ka_stays_within_the_bound_on_a_pure_sign_label() {
    let (v, t) = pure_sign_data(50_000, 11);
    // Unbounded (domain-only) the fit runs away: this is the degenerate case the bounds exist for.
    let free = fit::<CvParams>(
        &v,
        &t,
        &FitOptions {
            bounds: FitBounds::UNBOUNDED,
            ..FitOptions::default()
        },
    )
    .unwrap();
    println!("unbounded {:?}", free.model);
    assert!(free.model.ka > 1000.0, "unbounded ka {}", free.model.ka);
    assert!(free.at_bounds.is_empty());
    // Default bounds: ka ends on its 200 s/rad bound, kc/kv still right.
    let r = fit::<CvParams>(&v, &t, &FitOptions::default()).unwrap();
    println!("bounded {:?} {:?}", r.model, r.at_bounds);
    let ka_max = FitBounds::default().ka_max;
    assert_eq!(ka_max, 200.0);
    assert!(r.model.ka <= ka_max * (1.0 + 1e-12), "ka {}", r.model.ka);
    close("ka", r.model.ka, ka_max, 1e-6);
    assert_eq!(r.at_bounds, ["ka=max"]);
    close("kc", r.model.kc, 1.6, 0.03);
    close("kv", r.model.kv, 0.3, 0.1);
    // A user bound (as from `frictl fit --ka-max 50`) is honoured the same way, by both solvers.
    for method in [Method::Lm, Method::Adam] {
        let opts = FitOptions {
            method,
            adam_epochs: 500,
            adam_loss: Loss::Mse,
            bounds: FitBounds {
                ka_max: 50.0,
                ..FitBounds::default()
            },
            ..FitOptions::default()
        };
        let r = fit::<CvParams>(&v, &t, &opts).unwrap();
        assert!(
            r.model.ka <= 50.0 * (1.0 + 1e-12),
            "{method:?}: ka {}",
            r.model.ka
        );
        println!("{method:?} ka_max 50: {:?} {:?}", r.model, r.at_bounds);
        // The optimum presses against the bound (kc absorbs the slower tanh, so it is not checked).
        close("ka", r.model.ka, 50.0, 0.02);
    }
}

#[test]
fn scv_bounds_hold_when_binding_and_do_not_bias_a_well_posed_fit() {
    // Well-posed SCV data inside the default bounds: the known parameters are recovered, no bound
    // is active, and the fit equals the unbounded one.
    let truth = ScvParams {
        kc: 2.0,
        ka: 40.0,
        kv: 0.8,
        ks: 5.0,
        vs: 0.2,
        alpha: 1.2,
    };
    let (v, t) = data(&truth, 100_000, 2.5, 0.05, 21);
    let r = fit::<ScvParams>(&v, &t, &FitOptions::default()).unwrap();
    let m = r.model;
    println!("fitted {m:?} {:?}", r.at_bounds);
    assert!(r.at_bounds.is_empty(), "{:?}", r.at_bounds);
    close("kc", m.kc, truth.kc, 0.05);
    close("kv", m.kv, truth.kv, 0.05);
    close("ks", m.ks, truth.ks, 0.05);
    close("vs", m.vs, truth.vs, 0.1);
    close("alpha", m.alpha, truth.alpha, 0.1);
    close("ka", m.ka, truth.ka, 0.2);
    let free = fit::<ScvParams>(
        &v,
        &t,
        &FitOptions {
            bounds: FitBounds::UNBOUNDED,
            ..FitOptions::default()
        },
    )
    .unwrap();
    close("rmse vs unbounded", r.rmse_nm, free.rmse_nm, 1e-6);

    // Binding bounds: a Stribeck peak ks = 20·kc with vs = 0.01 rad/s, fitted with ks ≤ 10·kc and
    // vs ≥ 0.05 rad/s and α ≤ 1: every constraint holds and is reported.
    let spike = ScvParams {
        kc: 1.0,
        ka: 100.0,
        kv: 0.3,
        ks: 20.0,
        vs: 0.04,
        alpha: 2.0,
    };
    let (v, t) = data(&spike, 50_000, 1.0, 0.05, 22);
    let b = FitBounds {
        vs_min: 0.05,
        alpha_max: 1.0,
        ..FitBounds::default()
    };
    let r = fit::<ScvParams>(
        &v,
        &t,
        &FitOptions {
            bounds: b,
            ..FitOptions::default()
        },
    )
    .unwrap();
    let m = r.model;
    println!("spike fitted {m:?} {:?}", r.at_bounds);
    assert!(m.ks <= b.ks_max_ratio * m.kc * (1.0 + 1e-9), "{m:?}");
    assert!(m.vs >= b.vs_min * (1.0 - 1e-12), "{m:?}");
    assert!(m.alpha <= b.alpha_max * (1.0 + 1e-12), "{m:?}");
    assert!(m.ka <= b.ka_max * (1.0 + 1e-12), "{m:?}");
    assert!(!r.at_bounds.is_empty());
}

#[test]
fn invalid_bounds_are_an_error() {
    let (v, t) = data(&paper::CV_KNEE, 100, 3.0, 0.1, 31);
    for b in [
        FitBounds {
            ka_max: 1.0,
            ka_min: 2.0,
            ..FitBounds::default()
        },
        FitBounds {
            vs_min: 0.0,
            ..FitBounds::default()
        },
        FitBounds {
            alpha_max: f64::NAN,
            ..FitBounds::default()
        },
    ] {
        let r = fit::<CvParams>(
            &v,
            &t,
            &FitOptions {
                bounds: b,
                ..FitOptions::default()
            },
        );
        assert!(
            matches!(r, Err(frictionless_ident::fit::FitError::Bounds(_))),
            "{b:?}"
        );
    }
}

/// Rows for [`fit_scv_guarded`]: ṡ uniform in ±[v_lo, v_max] in time order, τ = the model at that
/// time + N(0, σ); `model(k)` gives the model of row k.
fn timed_rows(
    model: &dyn Fn(usize) -> ScvParams,
    n: usize,
    v_lo: f64,
    v_max: f64,
    sigma: f64,
    seed: u64,
) -> (Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sigma).unwrap();
    let v: Vec<f64> = (0..n)
        .map(|_| {
            let mag = rng.random_range(v_lo..v_max);
            if rng.random_bool(0.5) { mag } else { -mag }
        })
        .collect();
    let t = v
        .iter()
        .enumerate()
        .map(|(k, &x)| model(k).torque_nm(x) + noise.sample(&mut rng))
        .collect();
    (v, t)
}

/// The selections `frictl fit scv` makes: the SCV's rows down to 3 mrad/s, the CV's above 0.03 rad/s.
fn guarded(v: &[f64], t: &[f64]) -> frictionless_ident::scv_fit::ScvFit {
    let scv_rows = sliding_quadrant_mask(v, t, 0.003);
    let cv_rows = sliding_quadrant_mask(v, t, 0.03);
    fit_scv_guarded(
        &ScvFitInput {
            v_rad_s: v,
            tau_nm: t,
            scv_rows: &scv_rows,
            cv_rows: &cv_rows,
            low_speed_rad_s: 0.03,
            validation_fraction: 0.2,
        },
        &FitOptions::default(),
    )
    .unwrap()
}

/// A clear Stribeck hump (ks/kc = 2.5 over vs = 0.1 rad/s) with the low-speed rows in the data: the
/// guarded fit keeps the SCV, recovers ks/kc within 10 %, hits no bound, and beats the CV on fresh data.
#[test]
fn guarded_scv_recovers_a_stribeck_hump_and_hits_no_bound() {
    let truth = ScvParams {
        kc: 2.0,
        ka: 60.0,
        kv: 0.8,
        ks: 5.0,
        vs: 0.1,
        alpha: 1.5,
    };
    let (v, t) = timed_rows(&|_| truth, 60_000, 0.003, 2.0, 0.05, 41);
    let f = guarded(&v, &t);
    println!("{:?} {:?} {:?}", f.result.model, f.validation, f.bounds);
    assert_eq!(f.fallback, None);
    assert!(f.result.at_bounds.is_empty(), "{:?}", f.result.at_bounds);
    let m = f.result.model;
    close("ks/kc", m.ks / m.kc, truth.ks / truth.kc, 0.1);
    close("kc", m.kc, truth.kc, 0.1);
    let (v2, t2) = timed_rows(&|_| truth, 20_000, 0.0, 2.0, 0.05, 42);
    let (scv, _) = frictionless_ident::fit::errors(&m, &v2, &t2);
    let (cv, _) = frictionless_ident::fit::errors(&f.cv.model, &v2, &t2);
    assert!(scv < cv, "held out: SCV {scv} Nm, CV {cv} Nm");
}

/// No rows below the low-speed threshold: nothing shows a Stribeck hump, so the SCV is the CV
/// (ks = kc, the same torque at every speed) and says why.
#[test]
fn guarded_scv_without_low_speed_rows_is_the_cv_with_the_reason() {
    let truth = ScvParams {
        kc: 2.0,
        ka: 60.0,
        kv: 0.8,
        ks: 5.0,
        vs: 0.1,
        alpha: 1.5,
    };
    let (v, t) = timed_rows(&|_| truth, 30_000, 0.05, 2.0, 0.05, 43);
    let f = guarded(&v, &t);
    let why = f.fallback.as_deref().expect("a fallback");
    assert!(why.contains("no Stribeck region"), "{why}");
    assert!(why.contains("0 of"), "{why}");
    let m = f.result.model;
    assert_eq!(m.ks, m.kc);
    assert_eq!(f.result.model, scv_of_cv(&f.cv.model));
    for x in [-1.0, -0.01, 0.0, 0.002, 0.3, 2.0] {
        assert_eq!(m.torque_nm(x), f.cv.model.torque_nm(x), "at {x} rad/s");
    }
}

/// The friction changed at the end of the log (the hump gone): the SCV fitted before the validation
/// block is worse there than the CV, so the result is the CV with that reason.
#[test]
fn guarded_scv_that_loses_on_the_validation_block_is_the_cv() {
    let hump = ScvParams {
        kc: 2.0,
        ka: 60.0,
        kv: 0.8,
        ks: 6.0,
        vs: 0.1,
        alpha: 1.5,
    };
    let flat = ScvParams { ks: 2.0, ..hump };
    let n = 40_000;
    let (v, t) = timed_rows(
        &|k| if k < n * 8 / 10 { hump } else { flat },
        n,
        0.003,
        2.0,
        0.05,
        44,
    );
    let f = guarded(&v, &t);
    let why = f.fallback.as_deref().expect("a fallback");
    assert!(why.contains("not better than the CV"), "{why}");
    let s = f.validation.scv_rmse_nm.unwrap();
    assert!(s >= f.validation.cv_rmse_nm, "{:?}", f.validation);
    assert_eq!(f.result.model.ks, f.result.model.kc);
}

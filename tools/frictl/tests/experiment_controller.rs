//! The experiment controller on an in-process virtual joint (no IPC): computed-torque tracking of the
//! paper's sinusoid, with and without exact friction compensation, through the same torque-to-current
//! law as frictiond (i = (τ_des + τ̂_F)/(k_t·r), clamped).

use frictionless_experiment::controller::{ComputedTorque, Reference};
use frictionless_experiment::metrics::{self, TrackCriterion};
use frictionless_experiment::rig::JointSetup;
use frictionless_experiment::run::JointTrace;
use frictionless_sim::Plant;

/// Runs `periods` of `reference` at `kp`; `compensate` adds the true friction of the previous
/// sample (an oracle model) to τ_des.
fn track(
    preset: &str,
    reference: Reference,
    kp: f64,
    seconds: f64,
    compensate: bool,
) -> JointTrace {
    let setup = JointSetup::load(preset, &[]).unwrap();
    let mut params = setup.params.clone();
    params.initial_s_rad = reference.start_rad();
    let mut plant = Plant::from_params(params.clone(), 7).unwrap();
    let ctrl = ComputedTorque::paper(setup.link.as_ref(), kp);
    let (r, kt) = (params.gear_ratio_signed, params.kt_nm_per_a);
    let max_curr = params.i_max_a;
    let mut tr = JointTrace {
        kfc: if compensate { 1.0 } else { 0.0 },
        ..JointTrace::default()
    };
    let (mut s, mut sdot, mut tau_f_prev) = (params.initial_s_rad, 0.0, 0.0);
    let n = (seconds * 1000.0) as usize;
    for k in 0..n {
        let t = k as f64 * 1e-3;
        let sp = reference.at(t);
        let tau = ctrl.tau_des_nm(s, sdot, &sp);
        let hat = if compensate { tau_f_prev } else { 0.0 };
        let i = ((tau + hat) / (kt * r)).clamp(-max_curr, max_curr);
        let out = plant.step(i, 0.0);
        tr.t_s.push(t);
        tr.s_des_rad.push(sp.s_rad);
        tr.s_rad.push(s);
        tr.tau_des_nm.push(tau);
        tr.tau_f_hat_nm.push(hat);
        tr.tau_f_true_nm.push(out.truth.tau_f_nm);
        s = out.meas.s_rad;
        sdot = out.truth.state.s_dot_rad_s;
        tau_f_prev = out.truth.tau_f_nm;
    }
    tr
}

#[test]
fn exact_compensation_tracks_the_ankle_sine_where_none_does_not() {
    let reference = Reference::Sine {
        centre_rad: 0.0,
        amplitude_rad: 0.15,
        freq_hz: 0.25,
    };
    let crit = TrackCriterion {
        frac_of_amplitude: 0.1,
        skip_periods: 1.0,
    };
    let kp = 2000.0;
    let none = metrics::track(&track("ankle_roll", reference, kp, 12.0, false), 4.0, 12.0);
    let exact = metrics::track(&track("ankle_roll", reference, kp, 12.0, true), 4.0, 12.0);
    eprintln!("ankle Kp {kp}: none {none:?}\nexact {exact:?}");
    assert!(
        exact.rmse_rad <= crit.threshold_rad(0.15),
        "exact compensation tracks: {}",
        exact.rmse_rad
    );
    assert!(
        none.rmse_rad > 2.0 * exact.rmse_rad,
        "friction hurts without compensation: {} vs {}",
        none.rmse_rad,
        exact.rmse_rad
    );
    // the oracle's estimate is the true friction one sample late: small error
    assert!(exact.friction_est_rmse_nm < 0.5 * exact.friction_true_rms_nm);
}

#[test]
fn high_gain_tracks_the_knee_sine_without_compensation() {
    let reference = Reference::Sine {
        centre_rad: -0.8,
        amplitude_rad: 0.4,
        freq_hz: 0.2,
    };
    let hi = metrics::track(
        &track("knee", reference, reference_kp_hi(), 10.0, false),
        5.0,
        10.0,
    );
    let lo = metrics::track(&track("knee", reference, 3.0, 10.0, false), 5.0, 10.0);
    eprintln!("knee: hi {hi:?}\nlo {lo:?}");
    assert!(hi.rmse_rad < 0.1 * 0.4, "{}", hi.rmse_rad);
    assert!(
        lo.rmse_rad > hi.rmse_rad * 3.0,
        "{} vs {}",
        lo.rmse_rad,
        hi.rmse_rad
    );
    assert!(hi.rmse_rad.is_finite() && lo.rmse_rad.is_finite());
}

fn reference_kp_hi() -> f64 {
    3000.0
}

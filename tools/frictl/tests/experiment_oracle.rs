//! The `oracle` diagnostic through real processes (plant + frictiond in lockstep): frictiond runs no
//! model for the joint and the experiment controller adds frictiond's compensation law applied to
//! the plant's true friction to τ_des.
//!
//! Checks, on the ankle roll at a fixed K_p well below the uncompensated minimum: the oracle tracks
//! better than no compensation; the recorded τ_des minus the controller's own PD + feed-forward
//! part (recomputed here from the recorded measured state and the reference) equals kfc·τ_F,true
//! of the same row of the truth trace (clip included), and with the τ̂_F low-pass on, the same
//! Butterworth run over kfc·τ_F,true (scipy's design, applied to the whole recorded signal).
//!
//! Needs `frictiond` built next to `frictl` (`cargo build --workspace --bins`, as `tests/run.sh`).

use std::path::PathBuf;

use frictionless::filter::Butterworth;
use frictionless_experiment::controller::ComputedTorque;
use frictionless_experiment::metrics;
use frictionless_experiment::rig::JointSetup;
use frictionless_experiment::run::{JointPlan, JointTrace, TrialOptions, run_trial_with};
use frictionless_experiment::session::{Binaries, FrictionModel, LawSettings, Lpf, Mode};
use frictionless_experiment::suite::sine;

const ANKLE: usize = 1;
const KP: f64 = 3000.0;

fn run(model: FrictionModel, lpf: Lpf, duration_s: f64) -> (JointTrace, [JointSetup; 2]) {
    let bins = Binaries::with_frictl(PathBuf::from(env!("CARGO_BIN_EXE_frictl")))
        .expect("frictiond next to frictl (cargo build --workspace --bins)");
    let setups = JointSetup::both(&[]).unwrap();
    let spec = frictionless_experiment::run::TrialSpec {
        mode: Mode::Lockstep,
        duration_s,
        joints: vec![JointPlan {
            index: ANKLE,
            kp_per_s2: KP,
            reference: sine(ANKLE),
            pulse: None,
            model,
        }],
        seed: 5,
        sets: vec![],
        pinn_delta_theta_offset_motor_rad: vec![Some(0.0); 2],
        raw_friction: false,
        kfc: vec![],
    };
    let mut opts = TrialOptions {
        lpf: vec![None; ANKLE + 1],
        ..TrialOptions::default()
    };
    opts.lpf[ANKLE] = Some(lpf);
    let mut trace = run_trial_with(&bins, &setups, &spec, &opts).expect("closed-loop trial");
    (trace.joints.remove(0), setups)
}

/// τ_des minus the controller's PD + feed-forward part, per row.
fn added_term(tr: &JointTrace, setups: &[JointSetup; 2]) -> Vec<f64> {
    let ctrl = ComputedTorque::paper(setups[ANKLE].link.as_ref(), KP);
    let r = sine(ANKLE);
    (0..tr.t_s.len())
        .map(|i| {
            tr.tau_des_nm[i] - ctrl.tau_des_nm(tr.s_rad[i], tr.sdot_rad_s[i], &r.at(tr.t_s[i]))
        })
        .collect()
}

#[test]
fn oracle_beats_none_at_the_same_kp_and_adds_kfc_times_true_friction() {
    let periods = 2.0;
    let dur = periods / 0.25;
    let (none, _) = run(FrictionModel::None, Lpf::Off, dur);
    let (oracle, setups) = run(FrictionModel::Oracle, Lpf::Off, dur);
    let law = LawSettings::shipped(&setups[ANKLE].params.joint, None, Some(Lpf::Off)).unwrap();
    assert_eq!(oracle.kfc, law.kfc);
    assert!(law.kfc > 0.0 && law.kfc <= 1.0, "{law:?}");

    // plumbing: what the controller added is kfc·clip(τ_F,true) of the same row
    let added = added_term(&oracle, &setups);
    let mut max_diff: f64 = 0.0;
    let mut moving_rows = 0;
    for i in 0..added.len() {
        let f = oracle.tau_f_true_nm[i];
        assert!(f.is_finite(), "row {i}: no SimTruth");
        let clipped = if oracle.sdot_rad_s[i].abs() > law.joint_velocity_threshold_rad_s {
            f.clamp(-law.max_output_friction_nm, law.max_output_friction_nm)
        } else {
            f
        };
        max_diff = max_diff.max((added[i] - law.kfc * clipped).abs());
        if f.abs() > 0.5 {
            moving_rows += 1;
        }
        // the recorded τ̂_F keeps the daemon's one-row lag
        if i > 0 {
            assert!(
                (oracle.tau_f_hat_nm[i] - added[i - 1]).abs() < 1e-9,
                "row {i}: τ̂_F {} vs the term added at row {}: {}",
                oracle.tau_f_hat_nm[i],
                i - 1,
                added[i - 1]
            );
        }
    }
    assert!(
        moving_rows > added.len() / 4,
        "the true friction is mostly ≈ 0 ({moving_rows} of {} rows above 0.5 Nm)",
        added.len()
    );
    assert!(
        max_diff < 1e-9,
        "τ_des − PD/FF vs kfc·τ_F,true: max diff {max_diff}"
    );
    // none adds nothing
    let none_added = added_term(&none, &setups);
    assert!(none_added.iter().all(|a| a.abs() < 1e-9));

    // the bound does what it is for: better tracking than none at the same K_p
    let from = 1.0 / 0.25;
    let m_none = metrics::track(&none, from, dur);
    let m_oracle = metrics::track(&oracle, from, dur);
    eprintln!(
        "ankle roll K_p {KP}: tracking RMSE none {:.4} rad, oracle {:.4} rad",
        m_none.rmse_rad, m_oracle.rmse_rad
    );
    assert!(
        m_oracle.rmse_rad < m_none.rmse_rad,
        "oracle {} vs none {}",
        m_oracle.rmse_rad,
        m_none.rmse_rad
    );
}

#[test]
fn oracle_low_pass_is_the_butterworth_of_kfc_times_true_friction() {
    let cutoff_hz = 30.0;
    let (oracle, setups) = run(
        FrictionModel::Oracle,
        Lpf::Butterworth {
            order: 2,
            cutoff_hz,
        },
        1.5,
    );
    let law = LawSettings::shipped(&setups[ANKLE].params.joint, None, None).unwrap();
    let added = added_term(&oracle, &setups);
    let input: Vec<f64> = (0..added.len())
        .map(|i| {
            law.kfc
                * oracle.tau_f_true_nm[i]
                    .clamp(-law.max_output_friction_nm, law.max_output_friction_nm)
        })
        .collect();
    let filtered = Butterworth::lowpass(2, cutoff_hz, 1000.0)
        .unwrap()
        .filter(&input);
    let max_diff = added
        .iter()
        .zip(&filtered)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        max_diff < 1e-9,
        "filtered oracle term vs offline filter: {max_diff}"
    );
    // and it is filtered: it differs from the unfiltered term
    let raw_diff = added
        .iter()
        .zip(&input)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(raw_diff > 1e-3, "the LPF changed nothing ({raw_diff})");
}

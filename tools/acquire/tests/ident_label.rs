//! The label pipeline on simulated data recovers the simulator's true friction within the documented
//! noise floor, and the dataset file round-trips.
//!
//! A short knee run (one start: one sine block, one ramp pair, two tracking blocks at 0.5 and 1 Hz) and
//! a short ankle-roll run through `frictionless_acquire`, then `ident::preprocess` with the authors'
//! settings. On valid, active, sliding rows (|ṡ| > 0.03 rad/s):
//! - the paper's label differs from the truth by J_eq·φ̈ (reflected motor inertia, neglected by the
//!   paper) plus the pipeline's estimation noise (current noise through the 100 Hz filter, s̈ error of
//!   the smoother): measured 0.77 Nm knee / 0.39 Nm ankle roll, of which J_eq·φ̈ alone is 0.78 / 0.41
//!   (the J_eq·φ̈ term depends on the data's accelerations, not on the pipeline);
//! - the pipeline's own noise floor, label − truth − J_eq·φ̈_true, is documented in `ident::preprocess`
//!   (measured 0.34 Nm knee, 0.12 Nm ankle roll) and asserted here with a margin (< 0.4 / < 0.15);
//! - the ablation that subtracts J_eq·φ̂̈ (φ̂̈ from the motor encoder) brings the label itself within
//!   the reference targets (0.5 Nm knee, 0.2 Nm ankle roll): measured 0.29 / 0.07 Nm;
//! - `causal` changes the ṡ/s̈ columns only, never the label.

use frictionless_acquire::{LogRow, ProtocolConfig, log_meta, raw_log, run_offline, schedule};
use frictionless_dataset::Dataset;
use frictionless_ident::preprocess::{PreprocessConfig, preprocess};
use frictionless_sim::PlantParams;
use frictionless_sim::params::load_table;

fn simulate(preset: &str, sets: &[&str]) -> (PlantParams, Vec<LogRow>) {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let t = load_table(preset, None, &sets).unwrap();
    let p = PlantParams::from_table(&t).unwrap();
    let cfg = ProtocolConfig::from_table(&t).unwrap();
    let mut rows = Vec::new();
    run_offline(&p, &cfg, &schedule(&cfg), 7, &mut |r| {
        rows.push(*r);
        Ok(())
    })
    .unwrap();
    (p, rows)
}

const KNEE_SETS: &[&str] = &[
    "protocol.n_starts=1",
    "protocol.sines.amplitude_to_a=0.7",
    "protocol.sines.frequencies_hz=[0.45]",
    "protocol.ramps.slopes_a_per_s=[0.39]",
    "protocol.steps.enabled=false",
    "protocol.tracking.train.amplitudes_rad=[0.4]",
    "protocol.tracking.train.frequencies_hz=[0.5, 1.0]",
];

const ANKLE_SETS: &[&str] = &[
    "protocol.n_starts=1",
    "protocol.sines.amplitude_to_a=0.3",
    "protocol.sines.frequencies_hz=[0.8]",
    "protocol.ramps.enabled=false",
    "protocol.steps.enabled=false",
    "protocol.tracking.train.amplitudes_rad=[0.1]",
    "protocol.tracking.train.frequencies_hz=[1.0]",
];

/// RMS on valid, active, sliding (|ṡ| > 0.03) rows of: label − truth, label − truth − J_eq·φ̈_true
/// (the pipeline's own floor), and the row count.
#[allow(clippy::needless_range_loop)] // parallel columns indexed by sample
fn label_error(ds: &Dataset, j_eq: f64) -> (f64, f64, usize) {
    let truth = ds.tau_f_true_nm.as_ref().unwrap();
    let phi_ddot = ds.phi_ddot_rad_s2.as_ref().unwrap();
    let (mut e2, mut e2f, mut n) = (0.0, 0.0, 0usize);
    for k in 0..ds.len() {
        if ds.valid[k] && ds.active[k] && ds.sdot_rad_s[k].abs() > 0.03 {
            let e = ds.tau_f_label_nm[k] - truth[k];
            e2 += e * e;
            let ef = e - j_eq * phi_ddot[k];
            e2f += ef * ef;
            n += 1;
        }
    }
    ((e2 / n as f64).sqrt(), (e2f / n as f64).sqrt(), n)
}

/// Runs the pipeline (paper label and the J_eq·φ̂̈ ablation) and checks the documented bounds.
fn check_floor(
    name: &str,
    p: &PlantParams,
    rows: &[LogRow],
    floor_nm: f64,
    target_nm: f64,
) -> Dataset {
    let link = frictionless_sim::link::link_from_model(&p.link).unwrap();
    let m = log_meta(p);
    let cfg = PreprocessConfig::for_joint(&p.joint);
    let (ds, summary) = preprocess(&raw_log(rows, 1), &m, link.as_ref(), &cfg).unwrap();
    let (rms, floor, n) = label_error(&ds, p.j_eq_kgm2());
    let abl = PreprocessConfig {
        subtract_reflected_inertia_kgm2: p.j_eq_kgm2(),
        ..cfg.clone()
    };
    let (dsa, _) = preprocess(&raw_log(rows, 1), &m, link.as_ref(), &abl).unwrap();
    let (rms_abl, _, _) = label_error(&dsa, p.j_eq_kgm2());
    println!(
        "{name}: paper label RMS error {rms:.3} Nm, pipeline floor (minus true J_eq*phi_ddot) {floor:.3} Nm, \
         label with J_eq*phi_ddot_hat removed {rms_abl:.3} Nm; {n} sliding rows, {} chunks",
        summary.chunks
    );
    assert!(n > 2000, "{name}: too few sliding samples: {n}");
    assert!(
        floor < floor_nm,
        "{name}: pipeline floor {floor} Nm > documented {floor_nm}"
    );
    assert!(
        rms_abl < target_nm,
        "{name}: label without J_eq*phi_ddot {rms_abl} Nm > target {target_nm}"
    );
    assert!(
        rms_abl < rms,
        "{name}: removing J_eq*phi_ddot must reduce the error"
    );
    // The paper's label error is the floor plus the J_eq·φ̈ term, nothing else of size.
    assert!(rms < 1.3 * (rms_abl.hypot(rms_j(&ds, p.j_eq_kgm2()))) + 0.05);
    assert_eq!(summary.chunks as u32, rows.last().unwrap().chunk + 1);
    assert!(ds.delta_theta_motor_rad[0].abs() < 1e-12);
    ds
}

/// RMS of J_eq·φ̈_true on the sliding rows.
fn rms_j(ds: &Dataset, j_eq: f64) -> f64 {
    let phi_ddot = ds.phi_ddot_rad_s2.as_ref().unwrap();
    let v: Vec<f64> = (0..ds.len())
        .filter(|&k| ds.valid[k] && ds.active[k] && ds.sdot_rad_s[k].abs() > 0.03)
        .map(|k| j_eq * phi_ddot[k])
        .collect();
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn knee_label_recovers_true_friction_at_1khz_and_500hz() {
    let (p, rows) = simulate("knee", KNEE_SETS);
    let ds = check_floor("knee", &p, &rows, 0.4, 0.5);
    let (rms, _, _) = label_error(&ds, p.j_eq_kgm2());
    assert!(
        rms < 0.9,
        "knee paper label RMS error {rms} Nm (0.77 measured, seed 7)"
    );

    // The same run logged at 500 Hz and resampled to 1 kHz.
    let link = frictionless_sim::link::link_from_model(&p.link).unwrap();
    let m = log_meta(&p);
    let cfg = PreprocessConfig::for_joint(&p.joint);
    let (ds5, _) = preprocess(&raw_log(&rows, 2), &m, link.as_ref(), &cfg).unwrap();
    let (rms5, floor5, n5) = label_error(&ds5, p.j_eq_kgm2());
    println!("knee 500 Hz log: label RMS error {rms5:.3} Nm, floor {floor5:.3}, {n5} sliding rows");
    assert!((ds5.time_s[1] - ds5.time_s[0] - 1e-3).abs() < 1e-9);
    assert!(rms5 < 1.0, "500 Hz label RMS error {rms5} Nm");
    assert!(floor5 < 0.45, "500 Hz pipeline floor {floor5} Nm");

    // Causal processing changes the model-input columns only; the label is the non-causal one.
    let causal = PreprocessConfig {
        causal: true,
        ..cfg.clone()
    };
    let (dsc, _) = preprocess(&raw_log(&rows, 1), &m, link.as_ref(), &causal).unwrap();
    assert_eq!(dsc.tau_f_label_nm, ds.tau_f_label_nm);
    assert_eq!(dsc.valid, ds.valid);
    assert_ne!(dsc.sdot_rad_s, ds.sdot_rad_s);
    // How far the causal ṡ (what the daemon sees) is from the smoothed one, for the record.
    let e: f64 = dsc
        .sdot_rad_s
        .iter()
        .zip(&ds.sdot_rad_s)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / ds.len() as f64;
    println!(
        "knee causal vs smoothed sdot: RMS difference {:.4} rad/s",
        e.sqrt()
    );
}

#[test]
fn ankle_roll_label_is_within_the_documented_floor() {
    let (p, rows) = simulate("ankle_roll", ANKLE_SETS);
    check_floor("ankle_roll", &p, &rows, 0.15, 0.2);
}

#[test]
fn dataset_csv_round_trips() {
    let (p, rows) = simulate("ankle_roll", ANKLE_SETS);
    let link = frictionless_sim::link::link_from_model(&p.link).unwrap();
    let cfg = PreprocessConfig::for_joint(&p.joint);
    let (ds, _) = preprocess(&raw_log(&rows, 1), &log_meta(&p), link.as_ref(), &cfg).unwrap();
    let (rms, _, n) = label_error(&ds, p.j_eq_kgm2());
    println!("ankle roll: label RMS error {rms:.3} Nm on {n} sliding samples");
    let dir = std::env::temp_dir().join(format!("ident_label_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("ds.csv");
    ds.write_csv(&path).unwrap();
    let back = Dataset::read_csv(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    // NaN temperature (no sensor) breaks PartialEq; compare it separately.
    assert_eq!(back.temperature_c.len(), ds.temperature_c.len());
    let strip = |mut d: Dataset| {
        d.temperature_c.clear();
        d
    };
    assert_eq!(strip(back), strip(ds));
}

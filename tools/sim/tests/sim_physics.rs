//! Physical sanity tests of the virtual harmonic-drive joint (reference §2–§5).

use frictionless_sim::params::{PRESET_NAMES, load_table};
use frictionless_sim::{LinkDynamics, LinkModel, Plant, PlantParams};

fn params(preset: &str, sets: &[&str]) -> PlantParams {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    PlantParams::from_table(&load_table(preset, None, &sets).unwrap()).unwrap()
}

#[test]
fn presets_load_and_carry_the_reference_values() {
    for name in PRESET_NAMES {
        let p = PlantParams::preset(name).unwrap();
        assert!(
            p.gear_ratio_signed < 0.0,
            "{name}: left-leg ratios are negative"
        );
        assert_eq!(p.substeps_per_sample, 20);
        assert!((p.sample_period_s() - 1e-3).abs() < 1e-15);
    }
    let knee = PlantParams::preset("knee").unwrap();
    assert_eq!(knee.gear_ratio_signed, -100.0);
    assert_eq!(knee.kt_nm_per_a, 0.157);
    assert!((knee.j_eq_kgm2() - 0.23).abs() < 1e-12);
    let ankle = PlantParams::preset("ankle_roll").unwrap();
    assert_eq!(ankle.gear_ratio_signed, -160.0);
    assert_eq!(ankle.kt_nm_per_a, 0.0665);
    assert!((ankle.j_eq_kgm2() - 0.128).abs() < 1e-12);
    assert!(ankle.sensors.temperature_sensor && !knee.sensors.temperature_sensor);
}

#[test]
fn overrides_apply_and_unknown_keys_fail_with_the_key_named() {
    let p = params(
        "knee",
        &["plant.k1_nm_per_rad=20000", "plant.link.inertia_kgm2=0.4"],
    );
    assert_eq!(p.k1_nm_per_rad, 2e4);
    assert_eq!(
        p.link,
        LinkModel::Pendulum {
            inertia_kgm2: 0.4,
            gravity_amplitude_nm: 16.6,
            gravity_phase_rad: 0.0
        }
    );
    let table = load_table("knee", None, &["plant.k1_nm_per_radd=1".to_string()]).unwrap();
    let err = PlantParams::from_table(&table).unwrap_err().to_string();
    assert!(err.contains("k1_nm_per_radd"), "{err}");
    let table = load_table("knee", None, &["plant.k1_nm_per_rad=-5".to_string()]).unwrap();
    let err = PlantParams::from_table(&table).unwrap_err().to_string();
    assert!(err.contains("k1_nm_per_rad") && err.contains("-5"), "{err}");
    assert!(load_table("elbow", None, &[]).is_err());
    assert!(load_table("knee", None, &["no_equals_sign".to_string()]).is_err());
}

#[test]
fn joint_prefixed_set_applies_to_that_preset_only() {
    use frictionless_sim::params::check_set_joints;
    let sets = vec![
        "ankle_roll:plant.t0_min_c=31.5".to_string(),
        "plant.t0_max_c=33.0".to_string(),
    ];
    let t0_min = |preset: &str| {
        PlantParams::from_table(&load_table(preset, None, &sets).unwrap())
            .unwrap()
            .t0_min_c
    };
    let knee_default = PlantParams::preset("knee").unwrap().t0_min_c;
    assert_eq!(t0_min("ankle_roll"), 31.5);
    assert_eq!(t0_min("knee"), knee_default);
    for preset in ["knee", "ankle_roll"] {
        let p = PlantParams::from_table(&load_table(preset, None, &sets).unwrap()).unwrap();
        assert_eq!(
            p.t0_max_c, 33.0,
            "{preset}: an unprefixed --set applies to every preset"
        );
    }
    check_set_joints(&sets, &["knee", "ankle_roll"]).unwrap();
    let err = check_set_joints(&sets, &["knee"]).unwrap_err().to_string();
    assert!(
        err.contains("ankle_roll:plant.t0_min_c=31.5") && err.contains("knee"),
        "{err}"
    );
    // A colon inside the value is not a joint prefix.
    check_set_joints(&["plant.note=a:b".to_string()], &["knee"]).unwrap();
}

#[test]
fn params_file_is_deep_merged_over_the_preset() {
    let dir = std::env::temp_dir().join(format!("frictl-sim-params-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("over.toml");
    std::fs::write(
        &file,
        "[plant]\nmu_load = 0.0\n[plant.sensors]\ncurrent_noise_std_a = 0.5\n",
    )
    .unwrap();
    let t = load_table("ankle_roll", Some(&file), &[]).unwrap();
    let p = PlantParams::from_table(&t).unwrap();
    assert_eq!(p.mu_load, 0.0);
    assert_eq!(p.sensors.current_noise_std_a, 0.5);
    assert_eq!(p.f_s0_nm, 4.0, "untouched keys keep the preset value");
    std::fs::remove_dir_all(&dir).ok();
}

/// No input, no gravity: the stored energy (kinetic + flexspline + bristle) never increases.
#[test]
fn energy_never_increases_without_input() {
    for preset in PRESET_NAMES {
        let p = params(
            preset,
            &[
                "plant.link.gravity_amplitude_nm=0",
                "plant.sensors.current_noise_std_a=0",
            ],
        );
        let mut plant = Plant::from_params(p, 3).unwrap();
        let mut st = plant.state();
        st.s_dot_rad_s = 1.0;
        st.phi_dot_rad_s = -0.5;
        st.phi_rad = st.s_rad + 2e-4;
        st.i_a = 0.0;
        plant.set_state(st);
        let e0 = plant.stored_energy_j();
        assert!(e0 > 0.0);
        let mut prev = e0;
        for k in 0..3000 {
            plant.step(0.0, 0.0);
            let e = plant.stored_energy_j();
            // Semi-implicit Euler conserves a slightly shifted energy: allow 1e-9 of E0 per sample.
            assert!(
                e <= prev + 1e-9 * e0,
                "{preset}: energy rose at sample {k}: {prev} -> {e}"
            );
            prev = e;
        }
        assert!(
            prev < 0.05 * e0,
            "{preset}: energy is dissipated ({prev} of {e0})"
        );
    }
}

/// With ripple, load dependence and temperature effects off, the LuGre friction at constant velocity
/// settles to the Stribeck curve g_ss(ṡ) + σ2·ṡ and z to g_ss/σ0.
#[test]
fn lugre_steady_state_matches_the_stribeck_curve() {
    for preset in PRESET_NAMES {
        for &v in &[0.02, 0.1, 0.3, 1.0, -0.05, -0.5] {
            let p = params(
                preset,
                &[
                    "plant.e1=0",
                    "plant.e2=0",
                    "plant.mu_load=0",
                    "plant.beta_c_per_k=0",
                    "plant.beta_v_per_k=0",
                    "plant.link.gravity_amplitude_nm=0",
                    // huge inertias: the velocity stays put while the friction settles
                    "plant.link.inertia_kgm2=1e7",
                    "plant.j_motor_kgm2=1e3",
                ],
            );
            let (fc0, dfc, fs, vs, delta, s0, s2) = (
                p.f_c0_nm,
                p.delta_f_c_nm,
                p.f_s0_nm,
                p.v_s_rad_s,
                p.stribeck_exponent,
                p.sigma0_nm_per_rad,
                p.sigma2j_nms_per_rad,
            );
            let mut plant = Plant::from_params(p, 0).unwrap();
            let mut st = plant.state();
            st.s_dot_rad_s = v;
            st.phi_dot_rad_s = v;
            st.i_a = 0.0;
            plant.set_state(st);
            let mut sample = plant.step(0.0, 0.0);
            for _ in 0..300 {
                sample = plant.step(0.0, 0.0);
            }
            let t = sample.truth;
            let v_now = t.state.s_dot_rad_s;
            assert!(
                (v_now - v).abs() < 1e-3 * v.abs(),
                "velocity held: {v_now} vs {v}"
            );
            let fc = fc0 + dfc * (v_now / 1e-3).tanh();
            let g = fc + (fs - fc) * (-(v_now.abs() / vs).powf(delta)).exp();
            let expected = g * v_now.signum() + s2 * v_now;
            assert!(
                (t.tau_fj_nm - expected).abs() < 1e-3 * g,
                "{preset} v = {v}: tau_Fj {} vs Stribeck {expected}",
                t.tau_fj_nm
            );
            assert!((t.z_rad - g / s0 * v.signum()).abs() < 1e-3 * g / s0);
        }
    }
}

fn hold_torque(preset: &str, tau_joint_nm: f64, seconds: f64) -> (f64, f64, Plant) {
    let p = params(
        preset,
        &[
            "plant.link.gravity_amplitude_nm=0",
            "plant.e1=0",
            "plant.e2=0",
            "plant.t0_max_c=25",
            "plant.t0_min_c=25",
        ],
    );
    let i = tau_joint_nm / (p.gear_ratio_signed * p.kt_nm_per_a);
    let mut plant = Plant::from_params(p, 1).unwrap();
    let s0 = plant.state().s_rad;
    for _ in 0..(seconds * 1000.0) as usize {
        plant.step(i, 0.0);
    }
    let st = plant.state();
    (st.s_rad - s0, st.s_dot_rad_s, plant)
}

/// A constant joint torque below breakaway leaves the joint stuck (pre-sliding only); above it moves.
#[test]
fn stiction_holds_below_breakaway_and_releases_above() {
    for preset in PRESET_NAMES {
        let p = PlantParams::preset(preset).unwrap();
        let presliding = 2.0 * p.f_s0_nm / p.sigma0_nm_per_rad;
        for sign in [1.0, -1.0] {
            let (ds, sd, _) = hold_torque(preset, sign * 0.5 * p.f_s0_nm, 2.0);
            assert!(
                ds.abs() < presliding,
                "{preset}: stuck joint moved {ds} rad"
            );
            assert!(sd.abs() < 1e-3, "{preset}: stuck joint has velocity {sd}");
            let (ds, _, _) = hold_torque(preset, sign * (p.f_s0_nm + p.f_cm_nm) * 1.6, 1.0);
            assert!(
                ds * sign > 0.05,
                "{preset}: torque above breakaway must move the joint, moved {ds}"
            );
        }
    }
}

/// Robot conventions end to end: positive joint torque command → positive ṡ, θ_meas = r_signed·φ,
/// and the measured current keeps the commanded sign.
#[test]
fn signed_gear_ratio_conventions_hold_end_to_end() {
    for preset in PRESET_NAMES {
        let p = PlantParams::preset(preset).unwrap();
        let r = p.gear_ratio_signed;
        let (ds, sd, plant) = hold_torque(preset, 2.0 * (p.f_s0_nm + p.f_cm_nm), 0.3);
        assert!(
            ds > 0.0 && sd > 0.0,
            "{preset}: positive joint torque moves s up"
        );
        let i_cmd = 2.0 * (p.f_s0_nm + p.f_cm_nm) / (r * p.kt_nm_per_a);
        assert!(
            i_cmd < 0.0,
            "negative ratio: positive torque needs negative current"
        );
        let m = plant.measurement();
        assert!(
            m.i_meas_a * i_cmd > 0.0,
            "{preset}: measured current has the command's sign"
        );
        let st = plant.state();
        let q = std::f64::consts::TAU / 3600.0;
        assert!((m.theta_motor_rad - r * st.phi_rad).abs() <= 0.5 * q + 1e-12);
        assert!(
            m.omega_motor_rad_s * r * sd > 0.0,
            "{preset}: motor velocity has the sign of r*s_dot"
        );
        let qs = std::f64::consts::TAU / f64::from(1u32 << 18);
        assert!((m.s_rad - st.s_rad).abs() <= 0.5 * qs + 1e-15);
        assert!(
            ((m.s_rad / qs).round() * qs - m.s_rad).abs() < 1e-12,
            "joint encoder is quantised"
        );
    }
}

#[test]
fn same_seed_same_run_other_seed_differs() {
    let run = |seed: u64| {
        let mut plant =
            Plant::from_params(PlantParams::preset("ankle_roll").unwrap(), seed).unwrap();
        (0..2000)
            .map(|k| plant.step(0.8 * (k as f64 * 0.004).sin(), 0.0))
            .collect::<Vec<_>>()
    };
    let a = run(7);
    let b = run(7);
    assert!(a == b, "identical seeds give identical samples");
    let c = run(8);
    assert!(
        a.iter()
            .zip(&c)
            .any(|(x, y)| x.meas.i_meas_a != y.meas.i_meas_a)
    );
    assert_ne!(
        a[0].truth.state.temperature_c, c[0].truth.state.temperature_c,
        "T0 comes from the seed"
    );
}

#[test]
fn starts_pre_wound_to_hold_gravity() {
    let p = params("knee", &["plant.initial_s_rad=-1.0"]);
    let mut plant = Plant::from_params(p.clone(), 0).unwrap();
    let st = plant.state();
    let g = 16.6 * (-1.0f64).sin();
    let d = st.phi_rad - st.s_rad;
    assert!((p.k1_nm_per_rad * d + p.k3_nm_per_rad3 * d.powi(3) - g).abs() < 1e-9);
    // holding the gravity current keeps it there
    let i_hold = g / (p.gear_ratio_signed * p.kt_nm_per_a);
    for _ in 0..1000 {
        plant.step(i_hold, 0.0);
    }
    assert!((plant.state().s_rad + 1.0).abs() < 1e-3);
}

/// The URDF link model (fixed base, other joints at 0) reproduces the reference's ergoCub numbers, which
/// are also the pendulum presets' values.
#[test]
fn urdf_link_matches_the_ergocub_reference_values() {
    let urdf = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/fixtures/ergocub/ergoCubSN001.urdf"
    );
    assert!(
        std::path::Path::new(urdf).is_file(),
        "{urdf}: the vendored fixture is missing"
    );
    for (joint, inertia, amp) in [("l_knee", 0.574, 16.6), ("l_ankle_roll", 0.0054, 0.64)] {
        let link = frictionless_sim::link::link_from_model(&LinkModel::Urdf {
            urdf: urdf.to_string(),
            joint: joint.to_string(),
            other_joints_rad: Default::default(),
            gravity_m_s2: None,
        })
        .unwrap();
        let i = link.inertia_kgm2(0.3);
        assert!(
            (i - inertia).abs() < 0.03 * inertia,
            "{joint}: I_L {i} vs {inertia}"
        );
        let g = link.gravity_nm(-0.4);
        let want = amp * (-0.4f64).sin();
        assert!(
            (g - want).abs() < 0.05 * want.abs(),
            "{joint}: g(-0.4) {g} vs {want}"
        );
    }
    let err = frictionless_sim::link::link_from_model(&LinkModel::Urdf {
        urdf: urdf.to_string(),
        joint: "l_elbow_nope".to_string(),
        other_joints_rad: Default::default(),
        gravity_m_s2: None,
    })
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("l_elbow_nope"), "{err}");
}

/// A current that sweeps through breakaway both ways: stick, pre-sliding, stick-slip and fast sliding.
fn sweep_current_a(p: &PlantParams, k: usize) -> f64 {
    let t = k as f64 * 1e-3;
    let breakaway_a = (p.f_s0_nm + p.f_cm_nm) / (p.gear_ratio_signed.abs() * p.kt_nm_per_a);
    // amplitude slowly between 0.3× and 1.5× breakaway; frequency between 0.3 and 3 Hz
    let amp = breakaway_a * (0.9 + 0.6 * (0.05 * t).sin());
    let phase = std::f64::consts::TAU
        * (1.65 * t
            - 1.35 / (0.2 * std::f64::consts::TAU) * (0.2 * std::f64::consts::TAU * t).cos());
    amp * phase.sin()
}

/// Runs `n` samples of the sweep on the fast path and on the reference path (same seed) and returns
/// the largest differences (joint angle [rad], true friction [Nm], motor angle [rad]) and whether the
/// run slid (max |ṡ| in rad/s).
fn fast_vs_reference(preset: &str, sets: &[&str], seed: u64, n: usize) -> (f64, f64, f64, f64) {
    let p = params(preset, sets);
    let mut fast = Plant::from_params(p.clone(), seed).unwrap();
    let mut refp = Plant::from_params(p.clone(), seed).unwrap();
    refp.set_reference_math(true);
    assert!(!fast.reference_math() && refp.reference_math());
    let (mut ds, mut df, mut dphi, mut vmax) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        let i = sweep_current_a(&p, k);
        let a = fast.step(i, 0.0);
        let b = refp.step(i, 0.0);
        ds = ds.max((a.truth.state.s_rad - b.truth.state.s_rad).abs());
        dphi = dphi.max((a.truth.state.phi_rad - b.truth.state.phi_rad).abs());
        df = df.max((a.truth.tau_f_nm - b.truth.tau_f_nm).abs());
        vmax = vmax.max(b.truth.state.s_dot_rad_s.abs());
    }
    (ds, df, dphi, vmax)
}

/// The fast integration path follows the reference (libm every physics step) over a long stick-slip
/// run: the differences are rounding, far below the encoder resolution (2π/2¹⁸ ≈ 2.4e-5 rad).
#[test]
fn fast_path_tracks_the_reference_on_a_long_run() {
    for preset in PRESET_NAMES {
        // 120 simulated seconds, gravity and ripple on (the URDF-free pendulum presets)
        let (ds, df, dphi, vmax) = fast_vs_reference(preset, &[], 4, 120_000);
        eprintln!(
            "{preset}: max |Δs| {ds:.3e} rad, |Δφ| {dphi:.3e} rad, |Δτ_F| {df:.3e} Nm, max |ṡ| {vmax:.2} rad/s"
        );
        assert!(
            vmax > 0.5,
            "{preset}: the sweep must slide (max |ṡ| {vmax})"
        );
        assert!(ds < 1e-6, "{preset}: joint angle deviates {ds} rad");
        assert!(dphi < 1e-6, "{preset}: motor angle deviates {dphi} rad");
        assert!(df < 1e-3, "{preset}: friction deviates {df} Nm");
    }
}

/// The same on a link without a closed form (the fast path then calls the link every step).
#[test]
fn fast_path_matches_the_reference_with_a_generic_link() {
    struct Opaque(frictionless_sim::Pendulum);
    impl LinkDynamics for Opaque {
        fn inertia_kgm2(&self, s: f64) -> f64 {
            self.0.inertia_kgm2(s)
        }
        fn gravity_nm(&self, s: f64) -> f64 {
            self.0.gravity_nm(s)
        }
    }
    let p = params("knee", &[]);
    let pend = frictionless_sim::Pendulum {
        inertia_kgm2: 0.574,
        gravity_amplitude_nm: 16.6,
        gravity_phase_rad: 0.3,
    };
    let mut a = Plant::new(p.clone(), Opaque(pend), 9).unwrap();
    let mut b = Plant::new(p.clone(), pend, 9).unwrap();
    b.set_reference_math(true);
    for k in 0..20_000 {
        let i = sweep_current_a(&p, k);
        let x = a.step(i, 0.0);
        let y = b.step(i, 0.0);
        assert!(
            (x.truth.state.s_rad - y.truth.state.s_rad).abs() < 1e-6,
            "sample {k}"
        );
    }
}

mod determinism {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(12))]
        /// For any seed and excitation: the fast path is deterministic for a seed (bit for bit), the
        /// reference path too, and the two stay within rounding of each other.
        #[test]
        fn plant_is_deterministic_for_a_seed_on_both_paths(
            seed in any::<u64>(),
            preset_ix in 0usize..2,
            amp in 0.2f64..2.0,
            freq_hz in 0.2f64..4.0,
        ) {
            let preset = PRESET_NAMES[preset_ix];
            let p = params(preset, &[]);
            let breakaway_a = (p.f_s0_nm + p.f_cm_nm) / (p.gear_ratio_signed.abs() * p.kt_nm_per_a);
            let run = |reference: bool| {
                let mut plant = Plant::from_params(p.clone(), seed).unwrap();
                plant.set_reference_math(reference);
                (0..1500)
                    .map(|k| plant.step(amp * breakaway_a * (std::f64::consts::TAU * freq_hz * k as f64 * 1e-3).sin(), 0.0))
                    .collect::<Vec<_>>()
            };
            let (f1, f2, r1, r2) = (run(false), run(false), run(true), run(true));
            // Debug text prints every f64 exactly (and NaN temperature of sensor-less joints as NaN,
            // which `==` would call unequal)
            let text = |v: &Vec<frictionless_sim::Sample>| format!("{v:?}");
            prop_assert!(text(&f1) == text(&f2), "fast path not deterministic");
            prop_assert!(text(&r1) == text(&r2), "reference path not deterministic");
            for (k, (f, r)) in f1.iter().zip(&r1).enumerate() {
                prop_assert!((f.truth.state.s_rad - r.truth.state.s_rad).abs() < 1e-8, "sample {}: s", k);
                prop_assert!((f.truth.tau_f_nm - r.truth.tau_f_nm).abs() < 1e-4, "sample {}: tau_F", k);
                // same noise draws: the measured current differs only through the state
                prop_assert!((f.meas.i_meas_a - r.meas.i_meas_a).abs() <= 1.5e-3, "sample {}: i_meas", k);
            }
        }
    }
}

mod perturbed {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(16))]
        /// Over random friction, Stribeck, stiffness and ripple parameters (within and beyond the
        /// presets), the fast path (inlined exp/ln/tanh, rotations, regrouped sums) stays within
        /// the documented tolerance of the libm reference path: joint angle 1e-8 rad (the encoder
        /// resolves 2.4e-5 rad), true friction 1e-4 Nm, over 2 s of a sweep through breakaway.
        #[test]
        fn fast_path_stays_within_tolerance_of_the_reference(
            seed in any::<u64>(),
            preset_ix in 0usize..2,
            f_c_scale in 0.3f64..3.0,
            f_s_over_f_c in 1.0f64..4.0,
            v_s in 0.01f64..1.0,
            delta in 0.3f64..2.5,
            sigma0_scale in 0.3f64..3.0,
            sigma1_scale in 0.0f64..3.0,
            k1_scale in 0.5f64..2.0,
            mu_load in 0.0f64..0.2,
            e1 in 0.0f64..0.2,
            e2 in 0.0f64..0.2,
        ) {
            let preset = PRESET_NAMES[preset_ix];
            let base = params(preset, &[]);
            let f_c0 = base.f_c0_nm * f_c_scale;
            let sets = [
                format!("plant.f_c0_nm={f_c0}"),
                format!("plant.delta_f_c_nm={}", 0.1 * f_c0),
                format!("plant.f_s0_nm={}", f_c0 * f_s_over_f_c),
                format!("plant.v_s_rad_s={v_s}"),
                format!("plant.stribeck_exponent={delta}"),
                format!("plant.sigma0_nm_per_rad={}", base.sigma0_nm_per_rad * sigma0_scale),
                format!("plant.sigma1_nms_per_rad={}", base.sigma1_nms_per_rad * sigma1_scale),
                format!("plant.k1_nm_per_rad={}", base.k1_nm_per_rad * k1_scale),
                format!("plant.mu_load={mu_load}"),
                format!("plant.e1={e1}"),
                format!("plant.e2={e2}"),
            ];
            let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
            let p = params(preset, &sets);
            let mut fast = Plant::from_params(p.clone(), seed).unwrap();
            let mut refp = Plant::from_params(p.clone(), seed).unwrap();
            refp.set_reference_math(true);
            for k in 0..2000 {
                let i = sweep_current_a(&p, k);
                let a = fast.step(i, 0.0);
                let b = refp.step(i, 0.0);
                prop_assert!(
                    (a.truth.state.s_rad - b.truth.state.s_rad).abs() < 1e-8,
                    "sample {}: s {} vs {}", k, a.truth.state.s_rad, b.truth.state.s_rad
                );
                prop_assert!(
                    (a.truth.tau_f_nm - b.truth.tau_f_nm).abs() < 1e-4,
                    "sample {}: tau_F {} vs {}", k, a.truth.tau_f_nm, b.truth.tau_f_nm
                );
            }
        }
    }
}

/// An incremental motor encoder reads 0 at every power-up (start or reset at rest) and then the
/// same motion as an absolute one; the joint encoder is untouched.
#[test]
fn an_incremental_motor_encoder_reads_zero_at_every_power_up() {
    let pend = frictionless_sim::Pendulum {
        inertia_kgm2: 0.574,
        gravity_amplitude_nm: 16.6,
        gravity_phase_rad: 0.3,
    };
    let abs_p = params("knee", &["plant.initial_s_rad=0.7"]);
    let inc_p = params(
        "knee",
        &[
            "plant.initial_s_rad=0.7",
            "plant.sensors.motor_encoder=incremental",
        ],
    );
    let mut abs = Plant::new(abs_p.clone(), pend, 4).unwrap();
    let mut inc = Plant::new(inc_p, pend, 4).unwrap();
    let zero = abs.measurement().theta_motor_rad;
    assert!(zero.abs() > 10.0, "absolute θ at 0.7 rad: {zero}");
    assert_eq!(inc.measurement().theta_motor_rad, 0.0);
    for k in 0..3000 {
        let i = sweep_current_a(&abs_p, k);
        let a = abs.step(i, 0.0).meas;
        let b = inc.step(i, 0.0).meas;
        assert!(
            (b.theta_motor_rad - (a.theta_motor_rad - zero)).abs() < 1e-9,
            "sample {k}"
        );
        assert_eq!(a.s_rad, b.s_rad);
        assert!(
            (a.omega_motor_rad_s - b.omega_motor_rad_s).abs() < 1e-9,
            "sample {k}"
        );
    }
    // Another power-up at another pose: a new zero.
    inc.reset_at_rest(-0.4);
    assert_eq!(inc.measurement().theta_motor_rad, 0.0);
    let table = load_table(
        "knee",
        None,
        &["plant.sensors.motor_encoder=relative".into()],
    )
    .unwrap();
    let err = PlantParams::from_table(&table).unwrap_err().to_string();
    assert!(err.contains("relative"), "{err}");
}

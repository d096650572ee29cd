//! The coupled virtual leg: same drive and integrator as the single joint, rigid-body coupling, energy,
//! per-joint presets, link perturbation, input errors.

use frictionless_dynamics::Workspace;
use frictionless_sim::leg::{LEFT_LEG_JOINTS, LegParams, LegPlant, Perturbation};
use frictionless_sim::params::load_table;
use frictionless_sim::{LinkModel, Plant, PlantParams};

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../tests/fixtures/ergocub/ergoCubSN001.urdf"
);

fn sets(s: &[&str]) -> Vec<String> {
    s.iter().map(|x| x.to_string()).collect()
}

fn leg_with(s: &[&str]) -> LegParams {
    LegParams::from_toml_str(
        frictionless_sim::leg::LEG_PRESET_TOML,
        "<preset leg>",
        &sets(s),
    )
    .unwrap()
}

/// A leg of one joint is the single-joint plant with the URDF link: same drive equations, same
/// integrator, same sensors and random streams, so the two agree to rounding over 3 s of stick-slip.
#[test]
fn a_leg_of_one_joint_is_the_single_joint_plant() {
    for (preset, joint, amp_a) in [("knee", "l_knee", 2.5), ("ankle_roll", "l_ankle_roll", 1.2)] {
        let mut p = PlantParams::from_table(
            &load_table(preset, None, &sets(&["plant.initial_s_rad=-0.3"])).unwrap(),
        )
        .unwrap();
        p.link = LinkModel::Urdf {
            urdf: FIXTURE.to_string(),
            joint: joint.to_string(),
            other_joints_rad: Default::default(),
            gravity_m_s2: None,
        };
        let mut single = Plant::from_params(p.clone(), 11).unwrap();
        let mut leg = LegPlant::new(
            LegParams {
                urdf: FIXTURE.to_string(),
                joints: vec![p.clone()],
                locked_q_rad: Default::default(),
                perturbation: None,
            },
            11,
        )
        .unwrap();
        let i0 = single.state().i_a;
        assert!((leg.state(0).i_a - i0).abs() < 1e-12 * i0.abs().max(1.0));
        let (mut worst_s, mut worst_f) = (0.0f64, 0.0f64);
        for k in 0..3000 {
            let t = k as f64 * 1e-3;
            let i = i0 + amp_a * (std::f64::consts::TAU * 1.5 * t).sin();
            let a = single.step(i, 0.0);
            let b = leg.step(&[i], &[0.0]).unwrap()[0];
            worst_s = worst_s.max((a.truth.state.s_rad - b.truth.state.s_rad).abs());
            worst_f = worst_f.max((a.truth.tau_f_nm - b.truth.tau_f_nm).abs());
            assert_eq!(
                a.meas.i_meas_a, b.meas.i_meas_a,
                "{joint}: current noise stream"
            );
            assert_eq!(a.meas.time_s, b.meas.time_s);
            assert!(
                (a.truth.gravity_nm - b.truth.gravity_nm).abs() < 1e-9,
                "{joint}: gravity {} vs {}",
                a.truth.gravity_nm,
                b.truth.gravity_nm
            );
        }
        let moved = (leg.state(0).s_rad + 0.3).abs();
        assert!(moved > 0.01, "{joint}: the joint moved {moved} rad");
        println!("{joint}: leg vs single joint: s {worst_s:.3e} rad, τ_F {worst_f:.3e} Nm");
        assert!(worst_s < 1e-9, "{joint}: s differs by {worst_s} rad");
        assert!(worst_f < 1e-6, "{joint}: friction differs by {worst_f} Nm");
    }
}

/// Friction off and stiff transmissions: the leg follows the rigid-body trajectory
/// (M(q) + diag(J_eq))·q̈ + h(q, q̇) = r·k_t·i integrated with ABA at the same rate.
#[test]
fn a_stiff_frictionless_leg_follows_the_rigid_body_trajectory() {
    let params = leg_with(&[
        "plant.k1_nm_per_rad=2e5",
        "plant.k3_nm_per_rad3=0",
        "plant.d_t_nms_per_rad=5",
        "plant.tau_current_s=1e-7",
        "plant.i_max_a=100",
    ]);
    let mut leg = LegPlant::new(params.clone(), 3).unwrap();
    leg.set_friction(false);
    let robot = leg.robot().clone();
    let n = leg.dof();
    let order: Vec<usize> = leg
        .joint_names()
        .map(|j| robot.joint_index(j).unwrap())
        .collect();
    let armature = leg.armature_robot_order().to_vec();
    let gain: Vec<f64> = params
        .joints
        .iter()
        .map(|p| p.gear_ratio_signed * p.kt_nm_per_a)
        .collect();
    let i_hold: Vec<f64> = (0..n).map(|k| leg.state(k).i_a).collect();
    // rigid reference, robot order
    let mut q = leg.q_robot_order().to_vec();
    let mut qd = vec![0.0; n];
    let mut qdd = vec![0.0; n];
    let mut tau = vec![0.0; n];
    let mut i_now: Vec<f64> = i_hold.clone();
    let mut ws = Workspace::new(&robot);
    let dt = params.joints[0].dt_physics_s;
    let mut worst = 0.0f64;
    let mut travel = vec![0.0f64; n];
    let q0 = q.clone();
    for k in 0..500 {
        let t = k as f64 * 1e-3;
        // 6 Nm of joint torque at 2 Hz on every joint, phases apart
        let i_ref: Vec<f64> = (0..n)
            .map(|j| i_hold[j] + 6.0 / gain[j] * (std::f64::consts::TAU * 2.0 * t + j as f64).sin())
            .collect();
        leg.step(&i_ref, &vec![0.0; n]).unwrap();
        for _ in 0..params.joints[0].substeps_per_sample {
            for kk in 0..n {
                tau[order[kk]] = gain[kk] * i_now[kk];
            }
            robot
                .aba_with_armature(&mut ws, &q, &qd, &tau, Some(&armature), &mut qdd)
                .unwrap();
            for j in 0..n {
                qd[j] += qdd[j] * dt;
                q[j] += qd[j] * dt;
            }
            i_now.copy_from_slice(&i_ref);
        }
        for (j, (a, b)) in q.iter().zip(leg.q_robot_order()).enumerate() {
            worst = worst.max((a - b).abs());
            travel[j] = travel[j].max((a - q0[j]).abs());
        }
    }
    println!("leg vs rigid ABA: worst {worst:.3e} rad, travel {travel:?}");
    let least_travel = travel.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(least_travel > 0.02, "every joint moves: {travel:?}");
    assert!(
        worst < 2e-4,
        "leg vs rigid ABA: {worst} rad (travel {travel:?})"
    );
}

/// No friction, no damping, no current: the leg swings under gravity and its mechanical energy
/// (links, rotors, flexsplines) stays put to the integrator's tolerance.
#[test]
fn a_frictionless_unpowered_leg_conserves_energy() {
    let params = leg_with(&["plant.d_t_nms_per_rad=0", "plant.initial_s_rad=0.2"]);
    let mut leg = LegPlant::new(params, 5).unwrap();
    leg.set_friction(false);
    let n = leg.dof();
    for k in 0..n {
        let st = leg.state(k);
        leg.set_state(
            k,
            frictionless_sim::PlantState {
                i_a: 0.0,
                s_dot_rad_s: 0.5,
                phi_dot_rad_s: 0.5,
                ..st
            },
        );
    }
    let e0 = leg.energy_j().unwrap();
    let (mut lo, mut hi) = (e0, e0);
    let zeros = vec![0.0; n];
    let mut kinetic_seen = 0.0f64;
    for _ in 0..1000 {
        leg.step(&zeros, &zeros).unwrap();
        let e = leg.energy_j().unwrap();
        lo = lo.min(e);
        hi = hi.max(e);
        let speed: f64 = leg.qd_robot_order().iter().map(|v| v * v).sum::<f64>();
        kinetic_seen = kinetic_seen.max(speed.sqrt());
    }
    assert!(
        kinetic_seen > 1.0,
        "the leg swings: |q̇| up to {kinetic_seen}"
    );
    let spread = hi - lo;
    println!("energy {e0:.4} J, spread {spread:.3e} J, |q̇| up to {kinetic_seen:.2} rad/s");
    assert!(spread < 5e-3, "energy {e0} J wanders over [{lo}, {hi}]");
}

/// Each joint's drive is its own: the preset gives the joints different friction, and a
/// `JOINT:key=value` override changes that joint only.
#[test]
fn per_joint_presets_differ_and_a_joint_override_changes_that_joint_only() {
    let base = leg_with(&[]);
    let names: Vec<&str> = base.joints.iter().map(|p| p.joint.as_str()).collect();
    assert_eq!(names, LEFT_LEG_JOINTS);
    let mut f_c0: Vec<f64> = base.joints.iter().map(|p| p.f_c0_nm).collect();
    f_c0.sort_by(f64::total_cmp);
    f_c0.dedup();
    assert_eq!(f_c0.len(), 6, "six different Coulomb levels");
    let knee = &base.joints[3];
    assert_eq!(
        knee,
        &PlantParams::preset("knee").unwrap(),
        "the knee is the knee preset"
    );

    let over = leg_with(&["l_knee:plant.f_c0_nm=7", "l_knee:plant.f_s0_nm=12"]);
    for (a, b) in base.joints.iter().zip(&over.joints) {
        assert_eq!(a == b, a.joint != "l_knee", "{}", a.joint);
    }
    // The knee's true friction while it slides tells the two apart (mean |τ_Fj| over |ṡ| > 0.2 rad/s).
    let run = |params: LegParams| {
        let mut leg = LegPlant::new(params, 9).unwrap();
        let n = leg.dof();
        let hold: Vec<f64> = (0..n).map(|k| leg.state(k).i_a).collect();
        let (mut sum, mut count) = (vec![0.0f64; n], vec![0usize; n]);
        for k in 0..1500 {
            let t = k as f64 * 1e-3;
            let i: Vec<f64> = hold
                .iter()
                .zip(&leg.params().joints)
                .map(|(h, p)| h + 0.9 * p.i_max_a * (std::f64::consts::TAU * 1.0 * t).sin())
                .collect();
            let out = leg.step(&i, &vec![0.0; n]).unwrap();
            for (j, s) in out.iter().enumerate() {
                if s.truth.state.s_dot_rad_s.abs() > 0.2 {
                    sum[j] += s.truth.tau_fj_nm.abs();
                    count[j] += 1;
                }
            }
        }
        assert!(count[3] > 100, "the knee slides ({} samples)", count[3]);
        sum[3] / count[3] as f64
    };
    let (a, b) = (run(base), run(over));
    println!("knee sliding friction {a:.3} → {b:.3} Nm");
    assert!(b > a + 2.0, "knee sliding friction {a} → {b} Nm");
}

/// The plant's links can differ from the URDF by a seeded relative perturbation; without one they are
/// the URDF's.
#[test]
fn link_perturbation_is_seeded_and_bounded() {
    let mut p = leg_with(&[]);
    let nominal = LegPlant::new(p.clone(), 1).unwrap();
    for (a, b) in nominal
        .robot()
        .joints
        .iter()
        .zip(&nominal.nominal_robot().joints)
    {
        assert_eq!(a.inertia, b.inertia);
    }
    p.perturbation = Some(Perturbation {
        relative: 0.1,
        seed: 42,
    });
    let a = LegPlant::new(p.clone(), 1).unwrap();
    let b = LegPlant::new(p.clone(), 2).unwrap();
    let mut changed = 0;
    for ((x, y), z) in a
        .robot()
        .joints
        .iter()
        .zip(&a.nominal_robot().joints)
        .zip(&b.robot().joints)
    {
        assert_eq!(x.inertia, z.inertia, "the perturbation's seed is its own");
        let rel = (x.inertia.mass_kg / y.inertia.mass_kg - 1.0).abs();
        assert!(rel <= 0.1 + 1e-12, "{}: mass off by {rel}", x.name);
        if rel > 1e-3 {
            changed += 1;
        }
    }
    assert!(changed >= 4, "only {changed} of 6 masses changed");
    p.perturbation = Some(Perturbation {
        relative: 0.1,
        seed: 43,
    });
    let c = LegPlant::new(p.clone(), 1).unwrap();
    assert_ne!(c.robot().joints[3].inertia, a.robot().joints[3].inertia);
    // The knee's holding torque differs from the URDF's.
    let g_plant = a.samples()[3].truth.gravity_nm;
    let g_nominal = nominal.samples()[3].truth.gravity_nm;
    assert!(
        (g_plant - g_nominal).abs() > 1e-3,
        "{g_plant} vs {g_nominal}"
    );
    p.perturbation = Some(Perturbation {
        relative: 0.9,
        seed: 1,
    });
    let err = LegPlant::new(p, 1).err().unwrap().to_string();
    assert!(err.contains("perturbation.relative"), "{err}");
}

#[test]
fn leg_input_errors_name_what_is_wrong() {
    let err = LegParams::from_toml_str(
        frictionless_sim::leg::LEG_PRESET_TOML,
        "<preset leg>",
        &sets(&["l_elbow:plant.f_c0_nm=1"]),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("l_elbow"), "{err}");
    let mut p = leg_with(&[]);
    p.joints[1].joint = "l_hip_pitch".into();
    let err = LegPlant::new(p, 0).err().unwrap().to_string();
    assert!(err.contains("twice"), "{err}");
    let mut p = leg_with(&[]);
    p.joints[2].dt_physics_s = 1e-4;
    let err = LegPlant::new(p, 0).err().unwrap().to_string();
    assert!(
        err.contains("l_hip_yaw") && err.contains("integrator"),
        "{err}"
    );
    let mut p = leg_with(&[]);
    p.joints[0].joint = "l_hip_pitchh".into();
    let err = LegPlant::new(p, 0).err().unwrap().to_string();
    assert!(err.contains("l_hip_pitchh"), "{err}");
    let mut leg = LegPlant::new(leg_with(&[]), 0).unwrap();
    let err = leg.step(&[0.0; 5], &[0.0; 6]).unwrap_err().to_string();
    assert!(err.contains("i_ref_a") && err.contains('6'), "{err}");
}

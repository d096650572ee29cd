//! The project's own URDF (`config/urdf/virtual_leg.urdf`): structure, the link-side numbers the
//! virtual joints are built on (knee I_L ≈ 0.5–0.6 kg·m², g ≈ 16·sin s; ankle roll ≈ 0.005 kg·m²,
//! |g| ≤ 0.3 N·m), and the single-joint view against the full RNEA/CRBA.

use frictionless_dynamics::{DynamicsError, Robot, Workspace, virtual_leg};
use nalgebra::{DMatrix, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn leg() -> Robot {
    virtual_leg().expect("config/urdf/virtual_leg.urdf parses")
}

#[test]
fn structure_axes_and_limits() {
    let r = leg();
    assert_eq!(r.dof(), 15);
    let mut names: Vec<&str> = r.joint_names().collect();
    names.sort();
    let mut expect = vec!["torso_roll", "torso_pitch", "torso_yaw"];
    for s in ["l", "r"] {
        for j in [
            "hip_pitch",
            "hip_roll",
            "hip_yaw",
            "knee",
            "ankle_pitch",
            "ankle_roll",
        ] {
            expect.push(Box::leak(format!("{s}_{j}").into_boxed_str()));
        }
    }
    expect.sort();
    assert_eq!(names, expect);
    let knee = &r.joints[r.joint_index("l_knee").unwrap()];
    assert_eq!(knee.axis, Vector3::new(0.0, -1.0, 0.0));
    assert!((knee.lower - -1.8326).abs() < 1e-4 && (knee.upper - 0.1222).abs() < 1e-4);
    let roll = &r.joints[r.joint_index("l_ankle_roll").unwrap()];
    assert_eq!(roll.axis, Vector3::new(1.0, 0.0, 0.0));
    assert!((roll.lower - -0.4363).abs() < 1e-4 && (roll.upper - 0.4363).abs() < 1e-4);
    // Plausible humanoid lower body + lumped upper body.
    let m = r.total_mass_kg();
    assert!((40.0..60.0).contains(&m), "total mass {m}");
    for f in ["l_sole", "r_sole", "head", "l_hip_3"] {
        r.frame_id(f).unwrap();
    }
}

#[test]
fn knee_and_ankle_roll_link_side_numbers() {
    let r = leg();
    let q0 = vec![0.0; r.dof()];
    let knee = r.single_joint_view("l_knee", &q0).unwrap();
    let i_knee = knee.inertia_kg_m2();
    assert!((0.5..=0.6).contains(&i_knee), "knee I_L = {i_knee}");
    // g(s) = α cos s + β sin s with the leg hanging: mostly sin, amplitude ≈ 16 N·m.
    assert!((15.0..=17.5).contains(&knee.beta), "knee β = {}", knee.beta);
    assert!(
        knee.alpha.abs() < 0.1 * knee.beta,
        "knee α = {}",
        knee.alpha
    );
    let g_bent = knee.gravity_nm(-1.5);
    assert!((-17.5..=-14.5).contains(&g_bent), "knee g(-1.5) = {g_bent}");

    let roll = r.single_joint_view("l_ankle_roll", &q0).unwrap();
    let i_roll = roll.inertia_kg_m2();
    assert!(
        (0.004..=0.006).contains(&i_roll),
        "ankle roll I_L = {i_roll}"
    );
    let mut s = roll.lower;
    while s <= roll.upper {
        assert!(
            roll.gravity_nm(s).abs() <= 0.3,
            "ankle roll g({s}) = {}",
            roll.gravity_nm(s)
        );
        s += 0.01;
    }
    println!(
        "l_knee: I_L = {i_knee:.4} kg·m², g(s) = {:.3} cos s + {:.3} sin s",
        knee.alpha, knee.beta
    );
    println!(
        "l_ankle_roll: I_L = {i_roll:.5} kg·m², g(s) = {:.4} cos s + {:.4} sin s",
        roll.alpha, roll.beta
    );
}

#[test]
fn single_joint_view_matches_full_rnea_and_crba() {
    let r = leg();
    let n = r.dof();
    let mut ws = Workspace::new(&r);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for name in ["l_knee", "l_ankle_roll", "r_hip_roll", "torso_yaw"] {
        let j = r.joint_index(name).unwrap();
        for _ in 0..5 {
            let q_fixed: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let view = r.single_joint_view(name, &q_fixed).unwrap();
            let table = view.table(-2.0, 2.0, 4001).unwrap();
            for _ in 0..10 {
                let s = rng.random_range(-2.0..2.0);
                let sd = rng.random_range(-3.0..3.0);
                let sdd = rng.random_range(-10.0..10.0);
                let mut q = q_fixed.clone();
                q[j] = s;
                let mut qd = vec![0.0; n];
                let mut qdd = vec![0.0; n];
                qd[j] = sd;
                qdd[j] = sdd;
                let mut tau = vec![0.0; n];
                r.rnea(&mut ws, &q, &qd, &qdd, &mut tau).unwrap();
                // c(s, ṡ) ≡ 0, so the view reproduces the full RNEA at any ṡ.
                assert!(
                    (view.torque_nm(s, sdd) - tau[j]).abs() < 1e-9,
                    "{name}: {} vs {}",
                    view.torque_nm(s, sdd),
                    tau[j]
                );
                let mut m = DMatrix::zeros(n, n);
                r.mass_matrix(&mut ws, &q, &mut m).unwrap();
                assert!((view.inertia_kg_m2() - m[(j, j)]).abs() < 1e-12);
                // table: linear interpolation over 1 mrad steps, error ≤ |g|·h²/8
                let amp = view.alpha.hypot(view.beta);
                let bound = amp * 1e-6 / 8.0 + 1e-12;
                assert!((table.gravity_nm(s) - view.gravity_nm(s)).abs() <= bound);
            }
        }
    }
}

#[test]
fn single_joint_view_rejects_bad_input() {
    let r = leg();
    let e = r.single_joint_view("l_knee", &[0.0; 3]).unwrap_err();
    assert!(matches!(e, DynamicsError::Dimension { .. }), "{e}");
    let e = r
        .single_joint_view("l_sole", &vec![0.0; r.dof()])
        .unwrap_err();
    assert!(e.to_string().contains("l_sole"), "{e}");
    let v = r.single_joint_view("l_knee", &vec![0.0; r.dof()]).unwrap();
    assert!(v.table(1.0, 0.0, 10).is_err());
    assert!(v.table(0.0, 1.0, 1).is_err());
}

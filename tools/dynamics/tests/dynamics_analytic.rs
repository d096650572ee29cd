//! Closed-form checks of the URDF dynamics: single and double pendulum (M, C, g), a prismatic slider,
//! a free-floating body, CRBA against RNEA by columns, g(q) against RNEA at rest, lumping of fixed
//! joints, inertial rpy, reduced models and error reporting.

use frictionless_dynamics::{
    BaseState, DynamicsError, ExternalWrench, Force, GRAVITY_M_S2, Motion, Reduction, Robot,
    Workspace, virtual_leg,
};
use nalgebra::{DMatrix, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const G: f64 = GRAVITY_M_S2;

/// Double pendulum about +y: link i has mass m_i, COM at distance c_i below its joint, inertia iy_i
/// about its COM; joint 2 sits l1 below joint 1. Written in a deliberately shuffled file order.
fn double_pendulum_urdf(m1: f64, c1: f64, iy1: f64, l1: f64, m2: f64, c2: f64, iy2: f64) -> String {
    format!(
        r#"<robot name="dp">
  <joint name="j2" type="continuous">
    <origin xyz="0 0 {nl1}"/><parent link="l1"/><child link="l2"/><axis xyz="0 2 0"/>
  </joint>
  <link name="l2"><inertial><origin xyz="0 0 {nc2}"/><mass value="{m2}"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="{iy2}" iyz="0" izz="0.1"/></inertial></link>
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 {nc1}"/><mass value="{m1}"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="{iy1}" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j1" type="revolute">
    <origin xyz="0.3 -0.2 1.0"/><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="tip_fixed" type="fixed"><origin xyz="0 0 -0.5"/><parent link="l2"/><child link="tip"/></joint>
  <link name="tip"/>
</robot>"#,
        nl1 = -l1,
        nc1 = -c1,
        nc2 = -c2,
    )
}

struct Dp {
    m1: f64,
    c1: f64,
    i1: f64,
    l1: f64,
    m2: f64,
    c2: f64,
    i2: f64,
}

const DP: Dp = Dp {
    m1: 1.3,
    c1: 0.21,
    i1: 0.011,
    l1: 0.45,
    m2: 0.8,
    c2: 0.17,
    i2: 0.007,
};

fn dp_robot() -> Robot {
    let d = &DP;
    Robot::from_urdf_str(
        &double_pendulum_urdf(d.m1, d.c1, d.i1, d.l1, d.m2, d.c2, d.i2),
        "double_pendulum",
    )
    .unwrap()
}

/// Closed-form τ of the double pendulum (textbook Lagrangian, angles about +y, COM below the joint).
fn dp_tau(q: [f64; 2], qd: [f64; 2], qdd: [f64; 2]) -> [f64; 2] {
    let d = &DP;
    let (s2, c2q) = q[1].sin_cos();
    let m11 = d.i1
        + d.m1 * d.c1 * d.c1
        + d.i2
        + d.m2 * (d.l1 * d.l1 + d.c2 * d.c2 + 2.0 * d.l1 * d.c2 * c2q);
    let m12 = d.i2 + d.m2 * (d.c2 * d.c2 + d.l1 * d.c2 * c2q);
    let m22 = d.i2 + d.m2 * d.c2 * d.c2;
    let h = d.m2 * d.l1 * d.c2 * s2;
    let g1 = (d.m1 * d.c1 + d.m2 * d.l1) * G * q[0].sin() + d.m2 * d.c2 * G * (q[0] + q[1]).sin();
    let g2 = d.m2 * d.c2 * G * (q[0] + q[1]).sin();
    [
        m11 * qdd[0] + m12 * qdd[1] - h * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]) + g1,
        m12 * qdd[0] + m22 * qdd[1] + h * qd[0] * qd[0] + g2,
    ]
}

/// Puts a 2-joint vector given as (j1, j2) into the model's own index order.
fn by_name(r: &Robot, v: [f64; 2]) -> Vec<f64> {
    r.vector_from_names([("j1", v[0]), ("j2", v[1])]).unwrap()
}

#[test]
fn double_pendulum_matches_closed_form() {
    let r = dp_robot();
    assert_eq!(r.dof(), 2);
    let (i1, i2) = (r.joint_index("j1").unwrap(), r.joint_index("j2").unwrap());
    let mut ws = Workspace::new(&r);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut tau = vec![0.0; 2];
    for _ in 0..50 {
        let q = [rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0)];
        let qd = [rng.random_range(-4.0..4.0), rng.random_range(-4.0..4.0)];
        let qdd = [rng.random_range(-9.0..9.0), rng.random_range(-9.0..9.0)];
        r.rnea(
            &mut ws,
            &by_name(&r, q),
            &by_name(&r, qd),
            &by_name(&r, qdd),
            &mut tau,
        )
        .unwrap();
        let expect = dp_tau(q, qd, qdd);
        assert!((tau[i1] - expect[0]).abs() < 1e-10, "{tau:?} vs {expect:?}");
        assert!((tau[i2] - expect[1]).abs() < 1e-10, "{tau:?} vs {expect:?}");

        // CRBA vs the closed-form M
        let mut m = DMatrix::zeros(2, 2);
        r.mass_matrix(&mut ws, &by_name(&r, q), &mut m).unwrap();
        let d = &DP;
        let c2q = q[1].cos();
        let m11 = d.i1
            + d.m1 * d.c1 * d.c1
            + d.i2
            + d.m2 * (d.l1 * d.l1 + d.c2 * d.c2 + 2.0 * d.l1 * d.c2 * c2q);
        let m12 = d.i2 + d.m2 * (d.c2 * d.c2 + d.l1 * d.c2 * c2q);
        assert!((m[(i1, i1)] - m11).abs() < 1e-12);
        assert!((m[(i1, i2)] - m12).abs() < 1e-12);
        assert!((m[(i2, i1)] - m12).abs() < 1e-12);
    }
}

#[test]
fn single_pendulum_and_tip_force() {
    // Only j1 movable, j2 locked at 0: a single rigid pendulum (reduced model).
    let d = &DP;
    let red = Reduction {
        keep: vec!["j1".into()],
        locked_q: Default::default(),
    };
    let r = Robot::from_urdf_str_reduced(
        &double_pendulum_urdf(d.m1, d.c1, d.i1, d.l1, d.m2, d.c2, d.i2),
        "single",
        Some(&red),
    )
    .unwrap();
    assert_eq!(r.dof(), 1);
    let inertia = d.i1 + d.m1 * d.c1 * d.c1 + d.i2 + d.m2 * (d.l1 + d.c2).powi(2);
    let mgc = (d.m1 * d.c1 + d.m2 * (d.l1 + d.c2)) * G;
    let mut ws = Workspace::new(&r);
    let mut tau = [0.0];
    for &(q, qd, qdd) in &[(0.3, 2.0, -1.0), (-1.2, -3.0, 4.0), (2.5, 0.5, 0.0)] {
        r.rnea(&mut ws, &[q], &[qd], &[qdd], &mut tau).unwrap();
        // no velocity term for a single rigid body about a fixed axis
        let expect = inertia * qdd + mgc * f64::sin(q);
        assert!((tau[0] - expect).abs() < 1e-10, "{} vs {expect}", tau[0]);
    }
    // A horizontal force F (world x) at the tip, 0.5 m below l2 and l1+0.5+... : at q = 0 the tip is
    // at depth L = l1 + 0.5 below the joint; torque about +y of the force applied to the robot is
    // (r × F)·y = (z·Fx − x·Fz) = −L·Fx, and τ = g(q) − (r × F)·y.
    let tip = r.frame_id("tip").unwrap();
    let fx = 7.0;
    let ext = [ExternalWrench {
        frame: tip,
        wrench: Force::new(Vector3::zeros(), Vector3::new(fx, 0.0, 0.0)),
    }];
    r.rnea_with_wrenches(&mut ws, &[0.0], &[0.0], &[0.0], &ext, &mut tau)
        .unwrap();
    let l = d.l1 + 0.5;
    assert!((tau[0] - (l * fx)).abs() < 1e-10, "{}", tau[0]);
    // SingleJoint view agrees
    let sj = r.single_joint_view("j1", &[0.0]).unwrap();
    assert!((sj.inertia_kg_m2() - inertia).abs() < 1e-12);
    for s in [-2.0, -0.4, 0.0, 1.1] {
        assert!((sj.gravity_nm(s) - mgc * f64::sin(s)).abs() < 1e-10);
    }
}

#[test]
fn prismatic_slider_carries_weight() {
    let urdf = r#"<robot name="slider">
  <link name="base"/>
  <link name="carriage"><inertial><origin xyz="0.1 0 0"/><mass value="2.5"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="carriage"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="1" effort="100" velocity="1"/></joint>
</robot>"#;
    let r = Robot::from_urdf_str(urdf, "slider").unwrap();
    let mut ws = Workspace::new(&r);
    let mut tau = [0.0];
    r.rnea(&mut ws, &[0.4], &[1.5], &[2.0], &mut tau).unwrap();
    assert!((tau[0] - 2.5 * (2.0 + G)).abs() < 1e-12);
    let sj = r.single_joint_view("lift", &[0.0]).unwrap();
    assert!((sj.inertia - 2.5).abs() < 1e-12);
    assert!((sj.gravity_nm(0.7) - 2.5 * G).abs() < 1e-12);
}

#[test]
fn free_floating_body_newton_euler() {
    // One body, no joints: base wrench = I·a + v ×* I·v − I·g_base (Newton–Euler by hand).
    let urdf = r#"<robot name="brick">
  <link name="brick"><inertial><origin xyz="0.05 -0.02 0.1"/><mass value="3"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.03" iyz="0" izz="0.04"/></inertial></link>
</robot>"#;
    let r = Robot::from_urdf_str(urdf, "brick").unwrap();
    assert_eq!(r.dof(), 0);
    let mut ws = Workspace::new(&r);
    // At rest, identity orientation: the base must push up with the weight, moment c × f.
    let bw = r
        .rnea_floating(&mut ws, &BaseState::at_rest(), &[], &[], &[], &[], &mut [])
        .unwrap();
    let w = 3.0 * G;
    assert!((bw.lin - Vector3::new(0.0, 0.0, w)).norm() < 1e-12);
    let c = Vector3::new(0.05, -0.02, 0.1);
    assert!((bw.ang - c.cross(&Vector3::new(0.0, 0.0, w))).norm() < 1e-12);
    // Rotated and spinning: compare with the momentum-rate formula done independently here.
    let rot = UnitQuaternion::from_euler_angles(0.4, -0.3, 1.2);
    let omega = Vector3::new(0.5, -1.0, 2.0);
    let v = Vector3::new(0.3, 0.2, -0.1);
    let alpha = Vector3::new(-1.0, 0.5, 0.25);
    let acc = Vector3::new(0.2, -0.4, 1.0);
    let base = BaseState {
        pos_m: Vector3::new(1.0, 2.0, 3.0),
        orientation: rot,
        vel: Motion::new(omega, v),
        acc: Motion::new(alpha, acc),
    };
    let bw = r
        .rnea_floating(&mut ws, &base, &[], &[], &[], &[], &mut [])
        .unwrap();
    // COM velocity/acceleration in body axes (body-fixed derivative): vc = v + ω×c;
    // classical COM acceleration (body axes) = acc + α×c + ω×(v + ω×c)
    let m = 3.0;
    let a_com = acc + alpha.cross(&c) + omega.cross(&(v + omega.cross(&c)));
    let g_body = rot.inverse_transform_vector(&Vector3::new(0.0, 0.0, -G));
    let f = m * (a_com - g_body);
    let ic = nalgebra::Matrix3::new(0.02, 0.001, 0.0, 0.001, 0.03, 0.0, 0.0, 0.0, 0.04);
    let n_com = ic * alpha + omega.cross(&(ic * omega));
    let n_origin = n_com + c.cross(&f);
    assert!((bw.lin - f).norm() < 1e-10, "{:?} vs {f:?}", bw.lin);
    assert!(
        (bw.ang - n_origin).norm() < 1e-10,
        "{:?} vs {n_origin:?}",
        bw.ang
    );
}

fn random_q(r: &Robot, rng: &mut ChaCha8Rng, scale: f64) -> Vec<f64> {
    (0..r.dof())
        .map(|_| rng.random_range(-scale..scale))
        .collect()
}

#[test]
fn crba_equals_rnea_by_columns_and_gravity_equals_rnea_at_rest() {
    let r = virtual_leg().unwrap();
    let n = r.dof();
    let mut ws = Workspace::new(&r);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..10 {
        let q = random_q(&r, &mut rng, 1.5);
        let qd = random_q(&r, &mut rng, 2.0);
        let zeros = vec![0.0; n];
        let mut g = vec![0.0; n];
        let mut g2 = vec![0.0; n];
        r.gravity_torques(&mut ws, &q, &mut g).unwrap();
        r.rnea(&mut ws, &q, &zeros, &zeros, &mut g2).unwrap();
        assert_eq!(g, g2);
        let mut h = vec![0.0; n];
        let mut h2 = vec![0.0; n];
        r.bias_torques(&mut ws, &q, &qd, &mut h).unwrap();
        r.rnea(&mut ws, &q, &qd, &zeros, &mut h2).unwrap();
        assert_eq!(h, h2);

        let mut m = DMatrix::zeros(n, n);
        r.mass_matrix(&mut ws, &q, &mut m).unwrap();
        let mut col = vec![0.0; n];
        for j in 0..n {
            let mut e = vec![0.0; n];
            e[j] = 1.0;
            r.rnea(&mut ws, &q, &zeros, &e, &mut col).unwrap();
            for i in 0..n {
                assert!((m[(i, j)] - (col[i] - g[i])).abs() < 1e-12, "M[{i},{j}]");
            }
        }
        assert!((&m - m.transpose()).norm() < 1e-12);
        assert!(
            m.clone().cholesky().is_some(),
            "M must be positive definite"
        );
        // full RNEA = M qdd + h
        let qdd = random_q(&r, &mut rng, 5.0);
        let mut tau = vec![0.0; n];
        r.rnea(&mut ws, &q, &qd, &qdd, &mut tau).unwrap();
        let mq = &m * nalgebra::DVector::from_column_slice(&qdd);
        for i in 0..n {
            assert!((tau[i] - (mq[i] + h[i])).abs() < 1e-10);
        }
    }
}

#[test]
fn floating_base_consistent_with_fixed_base_and_floating_crba() {
    let r = virtual_leg().unwrap();
    let n = r.dof();
    let mut ws = Workspace::new(&r);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let q = random_q(&r, &mut rng, 1.2);
    let qd = random_q(&r, &mut rng, 2.0);
    let qdd = random_q(&r, &mut rng, 4.0);
    // Base at rest at identity: joint torques equal the fixed-base ones.
    let mut tf = vec![0.0; n];
    let mut tb = vec![0.0; n];
    r.rnea(&mut ws, &q, &qd, &qdd, &mut tf).unwrap();
    r.rnea_floating(&mut ws, &BaseState::at_rest(), &q, &qd, &qdd, &[], &mut tb)
        .unwrap();
    for i in 0..n {
        assert!((tf[i] - tb[i]).abs() < 1e-12);
    }
    // Static posture: the base wrench carries exactly the total weight.
    let zeros = vec![0.0; n];
    let bw = r
        .rnea_floating(
            &mut ws,
            &BaseState::at_rest(),
            &q,
            &zeros,
            &zeros,
            &[],
            &mut tb,
        )
        .unwrap();
    assert!((bw.lin.z - r.total_mass_kg() * G).abs() < 1e-9);
    assert!(bw.lin.x.abs() < 1e-9 && bw.lin.y.abs() < 1e-9);

    // Floating CRBA vs floating RNEA by columns, at a random base state.
    let mut mf = DMatrix::zeros(n + 6, n + 6);
    r.mass_matrix_floating(&mut ws, &q, &mut mf).unwrap();
    let base0 =
        BaseState::from_arrays([0.1, 0.2, 0.3], [0.1, -0.3, 0.2, 0.9], [0.0; 6], [0.0; 6]).unwrap();
    let mut t0 = vec![0.0; n];
    let w0 = r
        .rnea_floating(&mut ws, &base0, &q, &zeros, &zeros, &[], &mut t0)
        .unwrap();
    for c in 0..n + 6 {
        let mut acc = [0.0; 6];
        let mut e = vec![0.0; n];
        if c < 6 {
            acc[c] = 1.0;
        } else {
            e[c - 6] = 1.0;
        }
        let base =
            BaseState::from_arrays([0.1, 0.2, 0.3], [0.1, -0.3, 0.2, 0.9], [0.0; 6], acc).unwrap();
        let mut t = vec![0.0; n];
        let w = r
            .rnea_floating(&mut ws, &base, &q, &zeros, &e, &[], &mut t)
            .unwrap();
        let col: Vec<f64> = [w.lin - w0.lin, w.ang - w0.ang]
            .iter()
            .flat_map(|v| v.iter().copied().collect::<Vec<_>>())
            .chain(t.iter().zip(&t0).map(|(a, b)| a - b))
            .collect();
        for (i, x) in col.iter().enumerate() {
            assert!(
                (mf[(i, c)] - x).abs() < 1e-10,
                "Mf[{i},{c}] {} vs {x}",
                mf[(i, c)]
            );
        }
    }
    // The base block is the whole robot's mass.
    for i in 0..3 {
        assert!((mf[(i, i)] - r.total_mass_kg()).abs() < 1e-12);
    }
}

#[test]
fn fixed_joints_are_lumped_and_inertial_rpy_is_applied() {
    // The same body described two ways: (a) one link, (b) split across a fixed joint with a rotated
    // inertial frame. Dynamics must agree.
    let a = r#"<robot name="a"><link name="base"/>
  <link name="arm"><inertial><origin xyz="0.1 0.0 -0.2"/><mass value="2"/>
    <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0.3 0.4 0.5"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint></robot>"#;
    // Split: 1 kg + 1 kg with COMs at ±0.05 in x around (0.1, 0, -0.2): the parallel-axis terms add
    // m·d² = 2·1·0.05² = 0.005 to Iyy and Izz; the rotated inertial frame (yaw 90°) swaps Ixx/Iyy.
    let b = r#"<robot name="b"><link name="base"/>
  <link name="arm"><inertial><origin xyz="0.05 0.0 -0.2" rpy="0 0 1.5707963267948966"/><mass value="1"/>
    <inertia ixx="0.005" ixy="0" ixz="0" iyy="0.015" iyz="0" izz="0.0075"/></inertial></link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0.6 0.8 1.0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="weld" type="fixed"><origin xyz="0.15 0 -0.2" rpy="0 0 0"/><parent link="arm"/><child link="lump"/></joint>
  <link name="lump"><inertial><origin xyz="0 0 0"/><mass value="1"/>
    <inertia ixx="0.015" ixy="0" ixz="0" iyy="0.0" iyz="0" izz="0.0075"/></inertial></link>
</robot>"#;
    // (b) total at COM (0.1, 0, -0.2): Ixx = 0.015+0.015 = 0.03, Iyy = 0.005+0+0.005 = 0.01,
    // Izz = 0.0075+0.0075+0.005 = 0.02 — the same as (a).
    let ra = Robot::from_urdf_str(a, "a").unwrap();
    let rb = Robot::from_urdf_str(b, "b").unwrap();
    assert_eq!(rb.dof(), 1);
    let ia = ra.joints[0].inertia;
    let ib = rb.joints[0].inertia;
    assert!((ia.mass_kg - ib.mass_kg).abs() < 1e-12);
    assert!((ia.first_moment_kg_m - ib.first_moment_kg_m).norm() < 1e-12);
    assert!((ia.rot_inertia_kg_m2 - ib.rot_inertia_kg_m2).norm() < 1e-12);
    // axis normalised: (0.6, 0.8, 1.0) and (0.3, 0.4, 0.5) are the same unit axis
    assert!((ra.joints[0].axis - rb.joints[0].axis).norm() < 1e-15);
    assert!((rb.joints[0].axis.norm() - 1.0).abs() < 1e-15);
    let (mut wa, mut wb) = (Workspace::new(&ra), Workspace::new(&rb));
    let (mut ta, mut tb) = ([0.0], [0.0]);
    ra.rnea(&mut wa, &[0.7], &[1.3], &[-2.0], &mut ta).unwrap();
    rb.rnea(&mut wb, &[0.7], &[1.3], &[-2.0], &mut tb).unwrap();
    assert!((ta[0] - tb[0]).abs() < 1e-12);
    // the lumped link is still a frame of the moving body
    let lump = rb.frame_id("lump").unwrap();
    assert_eq!(rb.frames[lump.0].body, 1);
}

#[test]
fn reduced_model_locks_joints_at_given_positions() {
    let r = virtual_leg().unwrap();
    let full_n = r.dof();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let q_full = random_q(&r, &mut rng, 1.0);
    let keep = ["l_knee", "l_ankle_roll", "torso_pitch"];
    let locked_q = r
        .joint_names()
        .zip(&q_full)
        .filter(|(n, _)| !keep.contains(n))
        .map(|(n, &v)| (n.to_string(), v))
        .collect();
    let red = Reduction {
        keep: keep.iter().map(|s| s.to_string()).collect(),
        locked_q,
    };
    let rr = Robot::from_urdf_str_reduced(frictionless_dynamics::DEFAULT_URDF, "leg", Some(&red))
        .unwrap();
    assert_eq!(rr.dof(), 3);
    assert!((rr.total_mass_kg() - r.total_mass_kg()).abs() < 1e-12);
    // Static gravity on the kept joints equals the full model's with the same posture.
    let mut ws = Workspace::new(&r);
    let mut g = vec![0.0; full_n];
    r.gravity_torques(&mut ws, &q_full, &mut g).unwrap();
    let qr: Vec<f64> = rr
        .joint_names()
        .map(|n| q_full[r.joint_index(n).unwrap()])
        .collect();
    let mut wr = Workspace::new(&rr);
    let mut gr = vec![0.0; 3];
    rr.gravity_torques(&mut wr, &qr, &mut gr).unwrap();
    for (i, n) in rr.joint_names().enumerate() {
        assert!((gr[i] - g[r.joint_index(n).unwrap()]).abs() < 1e-12, "{n}");
    }
    // Kept-joint velocities produce the same torques too (locked joints static).
    let qd_r = [0.7, -1.1, 0.4];
    let qdd_r = [2.0, 1.0, -3.0];
    let mut qd = vec![0.0; full_n];
    let mut qdd = vec![0.0; full_n];
    for (i, n) in rr.joint_names().enumerate() {
        qd[r.joint_index(n).unwrap()] = qd_r[i];
        qdd[r.joint_index(n).unwrap()] = qdd_r[i];
    }
    let mut tau = vec![0.0; full_n];
    r.rnea(&mut ws, &q_full, &qd, &qdd, &mut tau).unwrap();
    rr.rnea(&mut wr, &qr, &qd_r, &qdd_r, &mut gr).unwrap();
    for (i, n) in rr.joint_names().enumerate() {
        assert!(
            (gr[i] - tau[r.joint_index(n).unwrap()]).abs() < 1e-10,
            "{n}"
        );
    }
}

#[test]
fn errors_name_the_culprit() {
    let r = virtual_leg().unwrap();
    let e = r.joint_index("l_knee_typo").unwrap_err();
    assert!(e.to_string().contains("l_knee_typo"), "{e}");
    let e = r.frame_id("nowhere").unwrap_err();
    assert!(e.to_string().contains("nowhere"), "{e}");
    let mut ws = Workspace::new(&r);
    let mut tau = vec![0.0; r.dof()];
    let e = r
        .rnea(&mut ws, &[0.0; 3], &[0.0; 15], &[0.0; 15], &mut tau)
        .unwrap_err();
    assert!(
        matches!(
            e,
            DynamicsError::Dimension {
                what: "q",
                expected: 15,
                got: 3
            }
        ),
        "{e}"
    );

    let bad_axis = r#"<robot name="x"><link name="a"/><link name="b"/>
  <joint name="spin" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint></robot>"#;
    let e = Robot::from_urdf_str(bad_axis, "bad_axis.urdf").unwrap_err();
    assert!(matches!(e, DynamicsError::BadAxis { .. }));
    assert!(
        e.to_string().contains("spin") && e.to_string().contains("bad_axis.urdf"),
        "{e}"
    );

    let neg_mass = r#"<robot name="x"><link name="a"/><link name="heavy"><inertial><mass value="-1"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <joint name="j" type="continuous"><parent link="a"/><child link="heavy"/><axis xyz="1 0 0"/></joint></robot>"#;
    let e = Robot::from_urdf_str(neg_mass, "neg.urdf").unwrap_err();
    assert!(
        e.to_string().contains("heavy") && e.to_string().contains("mass"),
        "{e}"
    );

    let two_roots = r#"<robot name="x"><link name="a"/><link name="b"/></robot>"#;
    let e = Robot::from_urdf_str(two_roots, "roots.urdf").unwrap_err();
    assert!(matches!(e, DynamicsError::Structure { .. }), "{e}");

    let floating = r#"<robot name="x"><link name="a"/><link name="b"/>
  <joint name="ff" type="floating"><parent link="a"/><child link="b"/></joint></robot>"#;
    let e = Robot::from_urdf_str(floating, "ff.urdf").unwrap_err();
    assert!(matches!(e, DynamicsError::UnsupportedJoint { .. }) && e.to_string().contains("ff"));

    let red = Reduction {
        keep: vec!["l_knee".into(), "no_such_joint".into()],
        locked_q: Default::default(),
    };
    let e = Robot::from_urdf_str_reduced(frictionless_dynamics::DEFAULT_URDF, "leg", Some(&red))
        .unwrap_err();
    assert!(e.to_string().contains("no_such_joint"), "{e}");

    let e = Robot::from_urdf_file("/nonexistent/robot.urdf").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/robot.urdf"), "{e}");

    let e = BaseState::from_arrays([0.0; 3], [0.0; 4], [0.0; 6], [0.0; 6]).unwrap_err();
    assert!(e.to_string().contains("quaternion"), "{e}");
}

/// Real robot descriptions carry geometry urdf-rs alone refuses (iCub's and Romeo's `<texture />`
/// without a filename, a `<mesh>` without one, a `<visual>` without `<geometry>`): the model's
/// dynamics do not depend on it, so it loads, with the same result as without the geometry.
#[test]
fn visual_collision_and_material_quirks_do_not_stop_a_model() {
    let plain = r#"<robot name="arm">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0 0 -0.2"/><mass value="1.5"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="50" velocity="3"/></joint>
</robot>"#;
    let quirky = r#"<?xml version="1.0"?>
<robot name="arm">
  <material name="skin"><color rgba="0.9 0.8 0.7 1"/><texture /></material>
  <material name="bare"/>
  <link name="base">
    <visual><geometry><mesh/></geometry><material name="skin"><texture /></material></visual>
  </link>
  <link name="upper"><inertial><origin xyz="0 0 -0.2"/><mass value="1.5"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial>
    <visual name="no geometry"/>
    <collision><origin xyz="0 0 -0.2"/><geometry><cylinder radius="0.05"/></geometry></collision>
    <visual><geometry><mesh filename="package://arm/meshes/upper.stl" scale="1 1 1"/></geometry></visual>
  </link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="50" velocity="3"/></joint>
</robot>"#;
    assert!(
        urdf_rs::read_from_string(quirky).is_err(),
        "the fixture must hold something urdf-rs itself refuses"
    );
    let (a, b) = (
        Robot::from_urdf_str(plain, "plain.urdf").unwrap(),
        Robot::from_urdf_str(quirky, "quirky.urdf").unwrap(),
    );
    let (mut wa, mut wb) = (Workspace::new(&a), Workspace::new(&b));
    let (mut ta, mut tb) = ([0.0], [0.0]);
    a.rnea(&mut wa, &[0.7], &[1.2], &[-3.0], &mut ta).unwrap();
    b.rnea(&mut wb, &[0.7], &[1.2], &[-3.0], &mut tb).unwrap();
    assert!(ta[0].abs() > 1.0);
    assert_eq!(ta, tb);
    assert_eq!(a.total_mass_kg(), b.total_mass_kg());

    // A xacro file of macros only (the UR description ships one as `ur3.urdf`) has no links.
    let e = Robot::from_urdf_str(
        r#"<robot xmlns:xacro="http://wiki.ros.org/xacro"><xacro:macro name="m"/></robot>"#,
        "macros.urdf",
    )
    .unwrap_err();
    assert!(e.to_string().contains("no <link>"), "{e}");

    // Text that is not XML is still urdf-rs's error, naming the source.
    let e = Robot::from_urdf_str("<robot name='x'><link name='a'>", "cut.urdf").unwrap_err();
    assert!(e.to_string().contains("cut.urdf"), "{e}");
}

/// A URDF path that is a FIFO or a device is refused before a byte is read (no hang, no unbounded
/// read), naming the path.
#[test]
fn a_urdf_path_that_is_not_a_regular_file_is_refused() {
    let dir = std::env::temp_dir().join(format!("frictionless-urdf-fifo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("robot.urdf");
    let _ = std::fs::remove_file(&fifo);
    let status = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(status.success());
    let e = Robot::from_urdf_file(&fifo).unwrap_err().to_string();
    assert!(
        e.contains(&*fifo.to_string_lossy()) && e.contains("FIFO"),
        "{e}"
    );
    let e = Robot::from_urdf_file("/dev/zero").unwrap_err().to_string();
    assert!(
        e.contains("/dev/zero") && e.contains("character device"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn frame_placement_follows_the_chain_of_the_double_pendulum() {
    let (l1, c2) = (0.7, 0.25);
    let robot = Robot::from_urdf_str(
        &double_pendulum_urdf(1.0, 0.3, 0.02, l1, 2.0, c2, 0.05),
        "dp",
    )
    .unwrap();
    let (q1, q2) = (0.4, -1.1);
    let q = robot.vector_from_names([("j1", q1), ("j2", q2)]).unwrap();
    let tip = robot
        .frame_placement(robot.frame_id("tip").unwrap(), &q)
        .unwrap();
    // Rotations about +y: the tip hangs 0.5 below joint 2, which hangs l1 below joint 1.
    let ry = |a: f64| *nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), a).matrix();
    let j1 = Vector3::new(0.3, -0.2, 1.0);
    let expected =
        j1 + ry(q1) * (Vector3::new(0.0, 0.0, -l1) + ry(q2) * Vector3::new(0.0, 0.0, -0.5));
    assert!(
        (tip.pos - expected).norm() < 1e-12,
        "{} vs {}",
        tip.pos,
        expected
    );
    assert!((tip.rot - ry(q1 + q2)).norm() < 1e-12);
    // The same through every body's placement.
    let bodies = robot.body_placements(&q).unwrap();
    for (k, f) in robot.frames.iter().enumerate() {
        let x = robot
            .frame_placement(frictionless_dynamics::FrameId(k), &q)
            .unwrap();
        let y = bodies[f.body].compose(&f.placement);
        assert!(
            (x.rot - y.rot).norm() < 1e-12 && (x.pos - y.pos).norm() < 1e-12,
            "{}",
            f.name
        );
    }
    assert!(
        robot
            .frame_placement(frictionless_dynamics::FrameId(999), &q)
            .is_err()
    );
    assert!(
        robot
            .frame_placement(robot.frame_id("tip").unwrap(), &q[..1])
            .is_err()
    );
}

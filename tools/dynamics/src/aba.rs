//! Forward dynamics by the articulated-body algorithm (ABA, Featherstone): q̈ from (q, q̇, τ) for a
//! fixed base, `M(q)·q̈ + C(q, q̇)·q̇ + g(q) = τ`.
//!
//! What it **is**: the three-pass O(n) recursion in world coordinates (Pinocchio's WORLD
//! convention: a child's articulated inertia adds to its parent's without a 6×6 transform), Pinocchio's `aba` for a fixed
//! base (root link welded to the world at identity, gravity [0, 0, −g] of the robot's g, no damping,
//! friction or rotor inertia), allocation-free into a caller-owned [`Workspace`]. Checked against
//! the CRBA/RNEA solve `M⁻¹·(τ − h)` (unit tests) and against Pinocchio on the ergoCub URDF
//! (`tools/dynamics/tests/dynamics_pinocchio.rs`).
//!
//! The articulated inertias are general symmetric 6×6 matrices, stored in the `(angular, linear)`
//! order of [`Motion`] and [`Force`]: a rigid body's inertia is `[[I_o, [h]×], [[h]×ᵀ, m·1]]` with
//! `h = m·c` its first moment.
//!
//! What it is **not**: a floating-base or contact solver, or an integrator (the simulator owns those).

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use super::algorithms::{Workspace, check_len};
use super::error::DynamicsError;
use super::robot::{JointKind, Robot};
use super::spatial::{Force, Motion, SpatialInertia, Transform, skew};

/// A motion or force as a 6-vector in `(angular, linear)` order.
#[inline(always)]
fn motion6(m: &Motion) -> Vector6<f64> {
    Vector6::new(m.ang.x, m.ang.y, m.ang.z, m.lin.x, m.lin.y, m.lin.z)
}

#[inline(always)]
fn force6(f: &Force) -> Vector6<f64> {
    Vector6::new(f.ang.x, f.ang.y, f.ang.z, f.lin.x, f.lin.y, f.lin.z)
}

#[inline(always)]
fn to_force(v: &Vector6<f64>) -> Force {
    Force::new(
        Vector3::new(v[0], v[1], v[2]),
        Vector3::new(v[3], v[4], v[5]),
    )
}

/// [`SpatialInertia::to_parent`] with the skew products written as outer products
/// (`[a]×[b]× = b·aᵀ − (a·b)·1`): two 3×3 products instead of five.
#[inline]
fn inertia_to_world(i: &SpatialInertia, x: &Transform) -> SpatialInertia {
    let m = i.mass_kg;
    let hr = x.rot * i.first_moment_kg_m;
    let p = x.pos;
    let i_rot = x.rot * i.rot_inertia_kg_m2 * x.rot.transpose();
    // −([h]×[p]× + [p]×[h]×) − m·[p]×[p]× = −(p·hᵀ + h·pᵀ) + 2(h·p)·1 − m·(p·pᵀ − |p|²·1)
    let hp = hr.dot(&p);
    let pp = p.dot(&p);
    let mut rot = i_rot - p * hr.transpose() - hr * p.transpose() - p * p.transpose() * m;
    let diag = 2.0 * hp + m * pp;
    rot[(0, 0)] += diag;
    rot[(1, 1)] += diag;
    rot[(2, 2)] += diag;
    SpatialInertia {
        mass_kg: m,
        first_moment_kg_m: hr + p * m,
        rot_inertia_kg_m2: rot,
    }
}

/// The 6×6 matrix of a rigid-body inertia (see the module doc).
#[inline]
pub(crate) fn inertia6(i: &SpatialInertia) -> Matrix6<f64> {
    let hx = skew(&i.first_moment_kg_m);
    let mut m = Matrix6::zeros();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&i.rot_inertia_kg_m2);
    m.fixed_view_mut::<3, 3>(0, 3).copy_from(&hx);
    m.fixed_view_mut::<3, 3>(3, 0).copy_from(&hx.transpose());
    m.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(Matrix3::identity() * i.mass_kg));
    m
}

impl Robot {
    /// Fixed-base forward dynamics (ABA): q̈ = M(q)⁻¹·(τ − C(q, q̇)·q̇ − g(q)) into `qdd`
    /// [rad/s² or m/s²], for joint torques `tau` [N·m or N]. Allocation-free.
    ///
    /// Fails on slices of the wrong length or a workspace of another model, and with
    /// [`DynamicsError::Singular`] when a joint's articulated inertia about its axis is not positive
    /// (a subtree without mass or inertia about the axis: M(q) is singular).
    pub fn aba(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        qd: &[f64],
        tau: &[f64],
        qdd: &mut [f64],
    ) -> Result<(), DynamicsError> {
        self.aba_with_armature(ws, q, qd, tau, None, qdd)
    }

    /// [`Robot::aba`] with a rotor inertia per joint (`armature` [kg·m² or kg], Pinocchio's
    /// `model.armature`): q̈ = (M(q) + diag(armature))⁻¹·(τ − h(q, q̇)), the rigid-transmission limit
    /// of a geared drive whose rotor inertia reflected to the joint is `armature`. `None` = no armature.
    pub fn aba_with_armature(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        qd: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
        qdd: &mut [f64],
    ) -> Result<(), DynamicsError> {
        self.aba_core(ws, q, None, qd, tau, armature, qdd)
    }

    /// [`Robot::aba_with_armature`] for an integrator that tracks the sine and cosine of its joint
    /// angles: `sin_cos_q[j]` = (sin q_j, cos q_j) places the revolute joints (no `sin_cos` per
    /// joint and call); prismatic joints still read `q`. The caller keeps the pairs consistent with `q`.
    #[allow(clippy::too_many_arguments)]
    pub fn aba_with_armature_sin_cos(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        sin_cos_q: &[(f64, f64)],
        qd: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
        qdd: &mut [f64],
    ) -> Result<(), DynamicsError> {
        check_len("sin_cos_q", self.dof(), sin_cos_q.len())?;
        self.aba_core(ws, q, Some(sin_cos_q), qd, tau, armature, qdd)
    }

    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn aba_core(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        sin_cos_q: Option<&[(f64, f64)]>,
        qd: &[f64],
        tau: &[f64],
        armature: Option<&[f64]>,
        qdd: &mut [f64],
    ) -> Result<(), DynamicsError> {
        let n = self.dof();
        check_len("q", n, q.len())?;
        check_len("qd", n, qd.len())?;
        check_len("tau", n, tau.len())?;
        check_len("qdd", n, qdd.len())?;
        if let Some(a) = armature {
            check_len("armature", n, a.len())?;
        }
        ws.check(self)?;
        // Everything in world (= root) coordinates, Pinocchio's WORLD convention: articulated
        // inertias of children add to their parent's without a transform.
        // Pass 1 (root → leaves): world placements, joint axes, velocities, velocity-product
        // accelerations c = v × S·q̇, rigid-body inertias and bias forces v ×* I·v.
        ws.v[0] = Motion::ZERO;
        ws.x[0] = Transform::identity();
        for (j, jt) in self.joints.iter().enumerate() {
            let b = j + 1;
            let xj = match (sin_cos_q, jt.kind) {
                (Some(sc), JointKind::Revolute) => jt.placement_sin_cos(sc[j].0, sc[j].1),
                _ => jt.placement(q[j]),
            };
            let x = ws.x[jt.parent_body].compose(&xj);
            let s = x.motion_to_parent(&self.joint_motion(j));
            let vj = Motion::new(s.ang * qd[j], s.lin * qd[j]);
            let v = ws.v[jt.parent_body] + vj;
            let inertia = inertia_to_world(&jt.inertia, &x);
            ws.a[b] = v.cross_motion(&vj);
            ws.f[b] = v.cross_force(&inertia.apply(&v));
            ws.ia[b] = inertia6(&inertia);
            ws.aba_s[j] = motion6(&s);
            ws.x[b] = x;
            ws.v[b] = v;
        }
        // Pass 2 (leaves → root): articulated inertias and bias forces, projected through each
        // joint into its parent. The root is welded to the world: nothing is propagated into it.
        for j in (0..n).rev() {
            let b = j + 1;
            let s6 = ws.aba_s[j];
            let ia = ws.ia[b];
            let u6 = ia * s6;
            let d = s6.dot(&u6) + armature.map_or(0.0, |a| a[j]);
            if !(d > 0.0 && d.is_finite()) {
                return Err(DynamicsError::Singular {
                    source_name: self.source.clone(),
                    joint: self.joints[j].name.clone(),
                    value: d,
                });
            }
            let f6 = force6(&ws.f[b]);
            let u = tau[j] - s6.dot(&f6);
            ws.aba_u[j] = u6;
            ws.aba_d[j] = d;
            ws.aba_tau[j] = u;
            let p = self.joints[j].parent_body;
            if p == 0 {
                continue;
            }
            let inv_d = 1.0 / d;
            // I^a = I^A − U·Uᵀ/D, written out (a fixed-size outer product through gemm is slower)
            let mut ia_a = ia;
            for c in 0..6 {
                let w = u6[c] * inv_d;
                for r in 0..6 {
                    ia_a[(r, c)] -= u6[r] * w;
                }
            }
            let pa = f6 + ia_a * motion6(&ws.a[b]) + u6 * (u * inv_d);
            ws.ia[p] += ia_a;
            ws.f[p] += to_force(&pa);
        }
        // Pass 3 (root → leaves): accelerations; the root's is −gravity (gravity as a base acceleration).
        ws.a[0] = Motion::new(Vector3::zeros(), -self.gravity_world_m_s2());
        for (j, jt) in self.joints.iter().enumerate() {
            let b = j + 1;
            let a_in = ws.a[jt.parent_body] + ws.a[b];
            let qdd_j = (ws.aba_tau[j] - ws.aba_u[j].dot(&motion6(&a_in))) / ws.aba_d[j];
            qdd[j] = qdd_j;
            ws.a[b] = a_in.add_scaled(&self.joint_motion_world(&ws.aba_s[j]), qdd_j);
        }
        Ok(())
    }

    #[inline(always)]
    fn joint_motion_world(&self, s6: &Vector6<f64>) -> Motion {
        Motion::new(
            Vector3::new(s6[0], s6[1], s6[2]),
            Vector3::new(s6[3], s6[4], s6[5]),
        )
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, DVector};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::robot::Reduction;

    /// q̈ by the CRBA/RNEA route: solve M(q)·q̈ = τ − h(q, q̇).
    fn qdd_by_crba(robot: &Robot, q: &[f64], qd: &[f64], tau: &[f64]) -> Vec<f64> {
        let n = robot.dof();
        let mut ws = Workspace::new(robot);
        let mut m = DMatrix::zeros(n, n);
        robot.mass_matrix(&mut ws, q, &mut m).unwrap();
        let mut h = vec![0.0; n];
        robot.bias_torques(&mut ws, q, qd, &mut h).unwrap();
        let rhs = DVector::from_iterator(n, tau.iter().zip(&h).map(|(t, h)| t - h));
        let chol = m.cholesky().expect("M(q) is positive definite");
        chol.solve(&rhs).iter().copied().collect()
    }

    fn check_model(robot: &Robot, seed: u64, cases: usize) -> f64 {
        let n = robot.dof();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut ws = Workspace::new(robot);
        let mut worst = 0.0f64;
        for _ in 0..cases {
            let q: Vec<f64> = (0..n).map(|_| rng.random_range(-1.5..1.5)).collect();
            let qd: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
            let tau: Vec<f64> = (0..n).map(|_| rng.random_range(-20.0..20.0)).collect();
            let mut qdd = vec![0.0; n];
            robot.aba(&mut ws, &q, &qd, &tau, &mut qdd).unwrap();
            let want = qdd_by_crba(robot, &q, &qd, &tau);
            let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for (j, (g, w)) in qdd.iter().zip(&want).enumerate() {
                let rel = (g - w).abs() / scale;
                worst = worst.max(rel);
                assert!(
                    rel <= 1e-9,
                    "{}: joint {}: ABA {g} vs M⁻¹(τ − h) {w} rad/s² (relative {rel:e})",
                    robot.source,
                    robot.joints[j].name
                );
            }
            // And back: RNEA of the ABA acceleration gives the torque again.
            let mut tau2 = vec![0.0; n];
            robot.rnea(&mut ws, &q, &qd, &qdd, &mut tau2).unwrap();
            for (a, b) in tau.iter().zip(&tau2) {
                assert!((a - b).abs() <= 1e-9 * 20.0, "RNEA(ABA(τ)) {b} vs τ {a}");
            }
        }
        worst
    }

    #[test]
    fn aba_equals_the_mass_matrix_solve_on_the_virtual_leg() {
        let robot = crate::virtual_leg().unwrap();
        check_model(&robot, 1, 50);
    }

    #[test]
    fn aba_equals_the_mass_matrix_solve_on_the_ergocub_left_leg() {
        let urdf = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../tests/fixtures/ergocub/ergoCubSN001.urdf"
        );
        let keep = [
            "l_hip_pitch",
            "l_hip_roll",
            "l_hip_yaw",
            "l_knee",
            "l_ankle_pitch",
            "l_ankle_roll",
        ];
        let red = Reduction {
            keep: keep.iter().map(|s| s.to_string()).collect(),
            locked_q: [
                ("torso_pitch".to_string(), 0.2),
                ("r_knee".to_string(), -0.5),
            ]
            .into_iter()
            .collect(),
        };
        let leg = Robot::from_urdf_file_reduced(urdf, Some(&red)).unwrap();
        assert_eq!(leg.dof(), 6);
        check_model(&leg, 2, 100);
        // The whole robot (57 joints, fingers included) as well.
        let whole = Robot::from_urdf_file(urdf).unwrap();
        check_model(&whole, 3, 5);
    }

    #[test]
    fn aba_with_armature_adds_it_to_the_mass_matrix_diagonal() {
        let robot = crate::virtual_leg().unwrap();
        let n = robot.dof();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut ws = Workspace::new(&robot);
        for _ in 0..20 {
            let q: Vec<f64> = (0..n).map(|_| rng.random_range(-1.5..1.5)).collect();
            let qd: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
            let tau: Vec<f64> = (0..n).map(|_| rng.random_range(-20.0..20.0)).collect();
            let arm: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..0.3)).collect();
            let mut qdd = vec![0.0; n];
            robot
                .aba_with_armature(&mut ws, &q, &qd, &tau, Some(&arm), &mut qdd)
                .unwrap();
            let mut m = DMatrix::zeros(n, n);
            robot.mass_matrix(&mut ws, &q, &mut m).unwrap();
            for (j, a) in arm.iter().enumerate() {
                m[(j, j)] += a;
            }
            let mut h = vec![0.0; n];
            robot.bias_torques(&mut ws, &q, &qd, &mut h).unwrap();
            let rhs = DVector::from_iterator(n, tau.iter().zip(&h).map(|(t, h)| t - h));
            let want = m.cholesky().unwrap().solve(&rhs);
            let scale = want.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for (g, w) in qdd.iter().zip(want.iter()) {
                assert!((g - w).abs() <= 1e-9 * scale, "{g} vs {w}");
            }
        }
    }

    #[test]
    fn inertia_to_world_is_to_parent() {
        let robot = crate::virtual_leg().unwrap();
        let q: Vec<f64> = (0..robot.dof()).map(|j| 0.3 * j as f64 - 1.0).collect();
        let x = robot.body_placements(&q).unwrap();
        for (j, jt) in robot.joints.iter().enumerate() {
            let a = jt.inertia.to_parent(&x[j + 1]);
            let b = inertia_to_world(&jt.inertia, &x[j + 1]);
            assert!((a.rot_inertia_kg_m2 - b.rot_inertia_kg_m2).norm() < 1e-12);
            assert!((a.first_moment_kg_m - b.first_moment_kg_m).norm() < 1e-14);
        }
    }

    #[test]
    fn aba_with_sin_cos_equals_aba() {
        let robot = crate::virtual_leg().unwrap();
        let n = robot.dof();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut ws = Workspace::new(&robot);
        let q: Vec<f64> = (0..n).map(|_| rng.random_range(-1.5..1.5)).collect();
        let qd: Vec<f64> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
        let tau: Vec<f64> = (0..n).map(|_| rng.random_range(-20.0..20.0)).collect();
        let sc: Vec<(f64, f64)> = q.iter().map(|x| x.sin_cos()).collect();
        let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
        robot.aba(&mut ws, &q, &qd, &tau, &mut a).unwrap();
        robot
            .aba_with_armature_sin_cos(&mut ws, &q, &sc, &qd, &tau, None, &mut b)
            .unwrap();
        assert_eq!(a, b);
        let err = robot
            .aba_with_armature_sin_cos(&mut ws, &q, &sc[1..], &qd, &tau, None, &mut b)
            .unwrap_err();
        assert!(
            matches!(
                err,
                DynamicsError::Dimension {
                    what: "sin_cos_q",
                    ..
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn aba_refuses_wrong_lengths_and_a_massless_subtree() {
        let robot = crate::virtual_leg().unwrap();
        let n = robot.dof();
        let mut ws = Workspace::new(&robot);
        let mut qdd = vec![0.0; n];
        let err = robot
            .aba(
                &mut ws,
                &vec![0.0; n - 1],
                &vec![0.0; n],
                &vec![0.0; n],
                &mut qdd,
            )
            .unwrap_err();
        assert!(
            matches!(err, DynamicsError::Dimension { what: "q", .. }),
            "{err}"
        );
        let text = r#"<robot name="r"><link name="a"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
            <link name="b"/>
            <joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"#;
        let r = Robot::from_urdf_str(text, "massless").unwrap();
        let mut ws = Workspace::new(&r);
        let mut qdd = [0.0];
        let err = r
            .aba(&mut ws, &[0.0], &[0.0], &[1.0], &mut qdd)
            .unwrap_err();
        assert!(err.to_string().contains("'j'"), "{err}");
    }
}

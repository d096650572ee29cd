//! One joint of a fixed-base robot with every other joint held at a fixed position: the link-side
//! dynamics the virtual harmonic-drive joint simulator needs, `I_L·s̈ + c(s, ṡ) + g(s) = τ`.
//!
//! With the other joints static, the subtree moved by the joint is one rigid body turning about (or
//! sliding along) a fixed axis, so:
//! - the link-side inertia `I_L = Sᵀ·I_subtree·S` does **not** depend on s,
//! - the velocity term c(s, ṡ) is identically 0 (a rigid body about a fixed axis has no
//!   centripetal torque about that axis),
//! - the gravity torque is exactly `g(s) = α·cos s + β·sin s` for a revolute joint and a constant for
//!   a prismatic one.
//!
//! So [`SingleJoint::gravity_nm`] is a closed form (one `sin_cos`, ~10–20 ns); [`SingleJointTable`]
//! is a precomputed uniform table with linear interpolation for callers that want no trigonometry at
//! all. Both are checked against the full RNEA/CRBA in the tests.
//!
//! What it is **not**: a model of a moving base or of several joints moving together.

use nalgebra::Vector3;

use super::error::DynamicsError;
use super::robot::{JointKind, Robot};
use super::spatial::Transform;

/// Link-side dynamics of one joint with the others held fixed (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SingleJoint {
    /// Revolute or prismatic.
    pub kind: JointKind,
    /// Link-side inertia about the axis [kg·m²] (revolute) or moved mass [kg] (prismatic).
    pub inertia: f64,
    /// Gravity coefficient α: g(s) = α·cos s + β·sin s [N·m] (prismatic: g = α [N]).
    pub alpha: f64,
    /// Gravity coefficient β [N·m] (0 for a prismatic joint).
    pub beta: f64,
    /// Joint lower limit from the URDF [rad or m].
    pub lower: f64,
    /// Joint upper limit from the URDF [rad or m].
    pub upper: f64,
}

impl SingleJoint {
    /// Link-side inertia about the joint axis [kg·m²]; independent of s (see the module doc).
    #[inline]
    pub fn inertia_kg_m2(&self) -> f64 {
        self.inertia
    }

    /// Gravity torque g(s) [N·m] at joint position `s_rad` (the torque the joint must apply to hold
    /// the link still; same sign as the fixed-base RNEA).
    #[inline]
    pub fn gravity_nm(&self, s_rad: f64) -> f64 {
        match self.kind {
            JointKind::Revolute => {
                let (sn, cs) = s_rad.sin_cos();
                self.alpha * cs + self.beta * sn
            }
            JointKind::Prismatic => self.alpha,
        }
    }

    /// Full link-side inverse dynamics I_L·s̈ + g(s) [N·m] (c(s, ṡ) ≡ 0).
    #[inline]
    pub fn torque_nm(&self, s_rad: f64, sdd_rad_s2: f64) -> f64 {
        self.inertia * sdd_rad_s2 + self.gravity_nm(s_rad)
    }

    /// Tabulates g(s) on `n ≥ 2` uniform points over `[s_min_rad, s_max_rad]`.
    pub fn table(
        &self,
        s_min_rad: f64,
        s_max_rad: f64,
        n: usize,
    ) -> Result<SingleJointTable, DynamicsError> {
        if n < 2 || !(s_min_rad.is_finite() && s_max_rad.is_finite() && s_max_rad > s_min_rad) {
            return Err(DynamicsError::BadInput {
                what: "single-joint table range/points".into(),
                value: format!("[{s_min_rad}, {s_max_rad}] with {n} points"),
            });
        }
        let step = (s_max_rad - s_min_rad) / (n - 1) as f64;
        let g = (0..n)
            .map(|i| self.gravity_nm(s_min_rad + step * i as f64))
            .collect();
        Ok(SingleJointTable {
            inertia_kg_m2: self.inertia,
            s_min_rad,
            inv_step: 1.0 / step,
            g_nm: g,
        })
    }
}

/// Uniform lookup table of g(s) with linear interpolation; clamps outside its range.
#[derive(Clone, Debug)]
pub struct SingleJointTable {
    /// Link-side inertia [kg·m²] (constant, see the module doc).
    pub inertia_kg_m2: f64,
    s_min_rad: f64,
    inv_step: f64,
    g_nm: Vec<f64>,
}

impl SingleJointTable {
    /// Interpolated gravity torque [N·m]; s outside the table range is clamped to its ends.
    #[inline]
    pub fn gravity_nm(&self, s_rad: f64) -> f64 {
        let last = self.g_nm.len() - 1;
        let u = ((s_rad - self.s_min_rad) * self.inv_step).clamp(0.0, last as f64);
        // NaN input: clamp keeps NaN, `as usize` maps it to 0, the result is NaN (propagated).
        let i = (u as usize).min(last - 1);
        let t = u - i as f64;
        self.g_nm[i] + t * (self.g_nm[i + 1] - self.g_nm[i])
    }
}

impl Robot {
    /// The link-side view of joint `name` with every other joint held at `q_fixed` (full joint vector
    /// in this model's index order; its entry for `name` is ignored). Fixed base.
    pub fn single_joint_view(
        &self,
        name: &str,
        q_fixed: &[f64],
    ) -> Result<SingleJoint, DynamicsError> {
        let j = self.joint_index(name)?;
        if q_fixed.len() != self.dof() {
            return Err(DynamicsError::Dimension {
                what: "q_fixed",
                expected: self.dof(),
                got: q_fixed.len(),
            });
        }
        let jt = &self.joints[j];
        // Pose of the parent body in the world (root = world).
        let mut chain = vec![];
        let mut k = jt.parent_body;
        while k != 0 {
            chain.push(k);
            k = self.joints[k - 1].parent_body;
        }
        let mut parent_in_world = Transform::identity();
        for &b in chain.iter().rev() {
            parent_in_world =
                parent_in_world.compose(&self.joints[b - 1].placement(q_fixed[b - 1]));
        }
        let joint0_in_world = parent_in_world.compose(&jt.tree);
        // Gravity in the joint frame at s = 0.
        let g0 = joint0_in_world.rot.transpose() * self.gravity_world_m_s2();
        // Composite inertia of the subtree in the moved body's frame (independent of s).
        let b = j + 1;
        let mut ic = jt.inertia;
        let mut descendants: Vec<(usize, Transform)> = vec![(b, Transform::identity())];
        let mut idx = 0;
        while idx < descendants.len() {
            let (d, d_in_b) = descendants[idx];
            for (cj, ct) in self.joints.iter().enumerate() {
                if ct.parent_body == d {
                    let c_in_b = d_in_b.compose(&ct.placement(q_fixed[cj]));
                    ic += ct.inertia.to_parent(&c_in_b);
                    descendants.push((cj + 1, c_in_b));
                }
            }
            idx += 1;
        }
        let a = jt.axis;
        let (inertia, alpha, beta) = match jt.kind {
            JointKind::Revolute => {
                // τ(s) = −(a × h)·g(s), g(s) = Rot(a, −s)·g0 = g0 cos s − (a × g0) sin s + a(a·g0)(1 − cos s)
                let k: Vector3<f64> = a.cross(&ic.first_moment_kg_m);
                (
                    a.dot(&(ic.rot_inertia_kg_m2 * a)),
                    -k.dot(&g0),
                    k.dot(&a.cross(&g0)),
                )
            }
            JointKind::Prismatic => (ic.mass_kg, -ic.mass_kg * a.dot(&g0), 0.0),
        };
        Ok(SingleJoint {
            kind: jt.kind,
            inertia,
            alpha,
            beta,
            lower: jt.lower,
            upper: jt.upper,
        })
    }
}

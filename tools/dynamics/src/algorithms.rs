//! Rigid-body algorithms on a [`Robot`]: RNEA (fixed and floating base, external wrenches), CRBA
//! mass matrix, gravity vector and bias forces.
//!
//! What it **is**: allocation-free evaluations into a caller-owned [`Workspace`] and output slices.
//! τ = M(q)·q̈ + C(q, q̇)·q̇ + g(q), gravity [0, 0, −g] in the world frame (g the robot's,
//! [`Robot::with_gravity_m_s2`]; default [`GRAVITY_M_S2`]), no damping, friction or rotor inertia.
//!
//! Floating base (Pinocchio's free-flyer convention): the base pose is position + unit quaternion
//! (x, y, z, w) of the root link in the world; the base velocity `ν = (v, ω)` is **body-fixed** (linear
//! velocity of the root-link origin and angular velocity, both in root-link coordinates); the base
//! acceleration is its time derivative `ν̇` (also body-fixed, i.e. Pinocchio's `a[0..6]`); the output
//! base wrench `(f, n)` is in root-link coordinates about its origin.
//!
//! External wrenches are applied **to** the robot (by the environment) at a named frame's origin,
//! expressed in that frame's coordinates: τ = M·ν̇ + h − Jᵀ·f_ext.
//!
//! Forward dynamics (ABA) is in [`super::aba`]. What it is **not**: integration (the simulator owns it).

use nalgebra::{DMatrix, Matrix6, UnitQuaternion, Vector3, Vector6};

use super::error::DynamicsError;
pub use super::robot::GRAVITY_M_S2;
use super::robot::{FrameId, JointKind, Robot};
use super::spatial::{Force, Motion, SpatialInertia, Transform};

/// Standard gravity's vector in the world frame [m/s²] ([`Robot::gravity_world_m_s2`] is a
/// model's).
pub fn gravity_world() -> Vector3<f64> {
    Vector3::new(0.0, 0.0, -GRAVITY_M_S2)
}

/// Preallocated scratch space for the algorithms (one per thread; reuse it across calls).
#[derive(Clone, Debug)]
pub struct Workspace {
    pub(crate) x: Vec<Transform>,
    pub(crate) v: Vec<Motion>,
    pub(crate) a: Vec<Motion>,
    pub(crate) f: Vec<Force>,
    ic: Vec<SpatialInertia>,
    /// ABA: articulated inertias per body.
    pub(crate) ia: Vec<Matrix6<f64>>,
    /// ABA: joint axis S in world coordinates per joint.
    pub(crate) aba_s: Vec<Vector6<f64>>,
    /// ABA: U = I^A·S per joint.
    pub(crate) aba_u: Vec<Vector6<f64>>,
    /// ABA: D = Sᵀ·I^A·S per joint.
    pub(crate) aba_d: Vec<f64>,
    /// ABA: u = τ − Sᵀ·p^A per joint.
    pub(crate) aba_tau: Vec<f64>,
}

impl Workspace {
    /// Scratch space sized for `robot`.
    pub fn new(robot: &Robot) -> Self {
        let nb = robot.dof() + 1;
        Self {
            x: vec![Transform::identity(); nb],
            v: vec![Motion::ZERO; nb],
            a: vec![Motion::ZERO; nb],
            f: vec![Force::ZERO; nb],
            ic: vec![SpatialInertia::zero(); nb],
            ia: vec![Matrix6::zeros(); nb],
            aba_s: vec![Vector6::zeros(); nb - 1],
            aba_u: vec![Vector6::zeros(); nb - 1],
            aba_d: vec![0.0; nb - 1],
            aba_tau: vec![0.0; nb - 1],
        }
    }

    pub(crate) fn check(&self, robot: &Robot) -> Result<(), DynamicsError> {
        check_len("workspace bodies", robot.dof() + 1, self.x.len())
    }
}

/// State of a floating base (Pinocchio free-flyer convention, see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaseState {
    /// Position of the root-link origin in the world [m].
    pub pos_m: Vector3<f64>,
    /// Orientation of the root link in the world.
    pub orientation: UnitQuaternion<f64>,
    /// Body-fixed base twist: `lin` [m/s] and `ang` [rad/s] in root-link coordinates.
    pub vel: Motion,
    /// Time derivative of the body-fixed twist [m/s², rad/s²].
    pub acc: Motion,
}

impl BaseState {
    /// Base at the world origin, identity orientation, at rest.
    pub fn at_rest() -> Self {
        Self {
            pos_m: Vector3::zeros(),
            orientation: UnitQuaternion::identity(),
            vel: Motion::ZERO,
            acc: Motion::ZERO,
        }
    }

    /// From JSON-style arrays: `quat_xyzw` is normalised (error if zero or not finite); `vel` and
    /// `acc` are `[vx, vy, vz, wx, wy, wz]` (linear first, as in Pinocchio).
    pub fn from_arrays(
        pos_m: [f64; 3],
        quat_xyzw: [f64; 4],
        vel: [f64; 6],
        acc: [f64; 6],
    ) -> Result<Self, DynamicsError> {
        let [x, y, z, w] = quat_xyzw;
        let qn = (x * x + y * y + z * z + w * w).sqrt();
        if !(qn.is_finite() && qn > 1e-9) {
            return Err(DynamicsError::BadInput {
                what: "base quaternion [x, y, z, w]".into(),
                value: format!("{quat_xyzw:?}"),
            });
        }
        for (what, vals) in [
            ("base pos", &pos_m[..]),
            ("base vel", &vel[..]),
            ("base acc", &acc[..]),
        ] {
            if vals.iter().any(|v| !v.is_finite()) {
                return Err(DynamicsError::BadInput {
                    what: what.into(),
                    value: format!("{vals:?}"),
                });
            }
        }
        let m6 = |a: [f64; 6]| {
            Motion::new(
                Vector3::new(a[3], a[4], a[5]),
                Vector3::new(a[0], a[1], a[2]),
            )
        };
        Ok(Self {
            pos_m: Vector3::from(pos_m),
            orientation: UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z)),
            vel: m6(vel),
            acc: m6(acc),
        })
    }
}

/// A wrench applied to the robot at a frame: `wrench` is in the frame's coordinates, about its origin.
#[derive(Clone, Copy, Debug)]
pub struct ExternalWrench {
    /// Where it acts.
    pub frame: FrameId,
    /// Moment [N·m] and force [N] in frame coordinates.
    pub wrench: Force,
}

pub(crate) fn check_len(
    what: &'static str,
    expected: usize,
    got: usize,
) -> Result<(), DynamicsError> {
    if expected == got {
        Ok(())
    } else {
        Err(DynamicsError::Dimension {
            what,
            expected,
            got,
        })
    }
}

impl Robot {
    #[inline]
    pub(crate) fn joint_motion(&self, j: usize) -> Motion {
        let jt = &self.joints[j];
        match jt.kind {
            JointKind::Revolute => Motion::new(jt.axis, Vector3::zeros()),
            JointKind::Prismatic => Motion::new(Vector3::zeros(), jt.axis),
        }
    }

    /// Core RNEA: root velocity/acceleration (gravity folded in) given; returns the root wrench.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn rnea_core(
        &self,
        ws: &mut Workspace,
        v0: Motion,
        a0: Motion,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        ext: &[ExternalWrench],
        tau: &mut [f64],
    ) -> Force {
        let i0 = &self.root_inertia;
        ws.v[0] = v0;
        ws.a[0] = a0;
        ws.f[0] = i0.apply(&a0) + v0.cross_force(&i0.apply(&v0));
        for (j, jt) in self.joints.iter().enumerate() {
            let b = j + 1;
            let p = jt.parent_body;
            let x = jt.placement(q[j]);
            let s = self.joint_motion(j);
            let vj = Motion::new(s.ang * qd[j], s.lin * qd[j]);
            let v = x.motion_to_child(&ws.v[p]) + vj;
            let a = x.motion_to_child(&ws.a[p]).add_scaled(&s, qdd[j]) + v.cross_motion(&vj);
            let i = &jt.inertia;
            ws.f[b] = i.apply(&a) + v.cross_force(&i.apply(&v));
            ws.x[b] = x;
            ws.v[b] = v;
            ws.a[b] = a;
        }
        for e in ext {
            let fr = &self.frames[e.frame.0];
            let w = fr.placement.force_to_parent(&e.wrench);
            ws.f[fr.body] = ws.f[fr.body] - w;
        }
        for j in (0..self.joints.len()).rev() {
            let b = j + 1;
            let fb = ws.f[b];
            tau[j] = self.joint_motion(j).dot(&fb);
            let p = self.joints[j].parent_body;
            let fp = ws.x[b].force_to_parent(&fb);
            ws.f[p] += fp;
        }
        ws.f[0]
    }

    fn check_joint_vecs(
        &self,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        tau: &[f64],
    ) -> Result<(), DynamicsError> {
        let n = self.dof();
        check_len("q", n, q.len())?;
        check_len("qd", n, qd.len())?;
        check_len("qdd", n, qdd.len())?;
        check_len("tau", n, tau.len())
    }

    /// Fixed-base inverse dynamics: τ = M(q)·q̈ + C(q, q̇)·q̇ + g(q) into `tau` [N·m or N].
    /// The root link is welded to the world with identity pose. Allocation-free.
    pub fn rnea(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        tau: &mut [f64],
    ) -> Result<(), DynamicsError> {
        self.check_joint_vecs(q, qd, qdd, tau)?;
        ws.check(self)?;
        let a0 = Motion::new(Vector3::zeros(), -self.gravity_world_m_s2());
        self.rnea_core(ws, Motion::ZERO, a0, q, qd, qdd, &[], tau);
        Ok(())
    }

    /// Fixed-base inverse dynamics with external wrenches: τ = M·q̈ + h − Jᵀ·f_ext.
    pub fn rnea_with_wrenches(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        ext: &[ExternalWrench],
        tau: &mut [f64],
    ) -> Result<(), DynamicsError> {
        self.check_joint_vecs(q, qd, qdd, tau)?;
        ws.check(self)?;
        self.check_frames(ext)?;
        let a0 = Motion::new(Vector3::zeros(), -self.gravity_world_m_s2());
        self.rnea_core(ws, Motion::ZERO, a0, q, qd, qdd, ext, tau);
        Ok(())
    }

    fn check_frames(&self, ext: &[ExternalWrench]) -> Result<(), DynamicsError> {
        for e in ext {
            if e.frame.0 >= self.frames.len() {
                return Err(DynamicsError::UnknownFrame {
                    source_name: self.source.clone(),
                    frame: format!("#{}", e.frame.0),
                });
            }
        }
        Ok(())
    }

    /// Floating-base inverse dynamics (see the module doc for the conventions). Writes the joint
    /// torques into `tau` and returns the base wrench (root-link coordinates, about its origin):
    /// the generalised force on the free-flyer, `[f; n]` in Pinocchio's order.
    #[allow(clippy::too_many_arguments)]
    pub fn rnea_floating(
        &self,
        ws: &mut Workspace,
        base: &BaseState,
        q: &[f64],
        qd: &[f64],
        qdd: &[f64],
        ext: &[ExternalWrench],
        tau: &mut [f64],
    ) -> Result<Force, DynamicsError> {
        self.check_joint_vecs(q, qd, qdd, tau)?;
        ws.check(self)?;
        self.check_frames(ext)?;
        let g_base = base
            .orientation
            .inverse_transform_vector(&self.gravity_world_m_s2());
        let a0 = Motion::new(base.acc.ang, base.acc.lin - g_base);
        Ok(self.rnea_core(ws, base.vel, a0, q, qd, qdd, ext, tau))
    }

    /// Gravity torques g(q) (fixed base) into `out`.
    pub fn gravity_torques(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        check_len("q", self.dof(), q.len())?;
        check_len("out", self.dof(), out.len())?;
        ws.check(self)?;
        let a0 = Motion::new(Vector3::zeros(), -self.gravity_world_m_s2());
        self.rnea_zero_vel(ws, a0, q, out);
        Ok(())
    }

    fn rnea_zero_vel(&self, ws: &mut Workspace, a0: Motion, q: &[f64], out: &mut [f64]) {
        // q̇ = q̈ = 0 without allocating zero slices: run the core with a static zero source.
        const CHUNK: usize = 64;
        static ZEROS: [f64; CHUNK] = [0.0; CHUNK];
        if q.len() <= CHUNK {
            let z = &ZEROS[..q.len()];
            self.rnea_core(ws, Motion::ZERO, a0, q, z, z, &[], out);
        } else {
            let z = vec![0.0; q.len()];
            self.rnea_core(ws, Motion::ZERO, a0, q, &z, &z, &[], out);
        }
    }

    /// Bias forces h(q, q̇) = C(q, q̇)·q̇ + g(q) (fixed base) into `out`.
    pub fn bias_torques(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        qd: &[f64],
        out: &mut [f64],
    ) -> Result<(), DynamicsError> {
        let n = self.dof();
        check_len("q", n, q.len())?;
        check_len("qd", n, qd.len())?;
        check_len("out", n, out.len())?;
        ws.check(self)?;
        let a0 = Motion::new(Vector3::zeros(), -self.gravity_world_m_s2());
        // q̈ = 0: the core only reads qdd[j]; use a zero view of the right length.
        const CHUNK: usize = 64;
        static ZEROS: [f64; CHUNK] = [0.0; CHUNK];
        if n <= CHUNK {
            self.rnea_core(ws, Motion::ZERO, a0, q, qd, &ZEROS[..n], &[], out);
        } else {
            let z = vec![0.0; n];
            self.rnea_core(ws, Motion::ZERO, a0, q, qd, &z, &[], out);
        }
        Ok(())
    }

    /// Composite inertias and placements for configuration `q` (fills `ws.x` and `ws.ic`).
    fn composite_inertias(&self, ws: &mut Workspace, q: &[f64]) {
        ws.ic[0] = self.root_inertia;
        for (j, jt) in self.joints.iter().enumerate() {
            ws.x[j + 1] = jt.placement(q[j]);
            ws.ic[j + 1] = jt.inertia;
        }
        for j in (0..self.joints.len()).rev() {
            let b = j + 1;
            let moved = ws.ic[b].to_parent(&ws.x[b]);
            ws.ic[self.joints[j].parent_body] += moved;
        }
    }

    /// Fixed-base joint-space mass matrix M(q) (CRBA) into the n×n matrix `m`.
    pub fn mass_matrix(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        m: &mut DMatrix<f64>,
    ) -> Result<(), DynamicsError> {
        let n = self.dof();
        check_len("q", n, q.len())?;
        check_len("mass matrix rows", n, m.nrows())?;
        check_len("mass matrix columns", n, m.ncols())?;
        ws.check(self)?;
        // Entries between joints on different branches stay zero.
        m.fill(0.0);
        self.composite_inertias(ws, q);
        for j in 0..n {
            let b = j + 1;
            let mut f = ws.ic[b].apply(&self.joint_motion(j));
            m[(j, j)] = self.joint_motion(j).dot(&f);
            let mut k = b;
            while let Some(p) = self.parent_body(k) {
                if p == 0 {
                    break;
                }
                f = ws.x[k].force_to_parent(&f);
                k = p;
                let v = self.joint_motion(k - 1).dot(&f);
                m[(k - 1, j)] = v;
                m[(j, k - 1)] = v;
            }
        }
        Ok(())
    }

    /// Floating-base mass matrix ((6 + n)×(6 + n), base first as `[v; ω]` body-fixed then joints).
    /// It does not depend on the base pose.
    pub fn mass_matrix_floating(
        &self,
        ws: &mut Workspace,
        q: &[f64],
        m: &mut DMatrix<f64>,
    ) -> Result<(), DynamicsError> {
        let n = self.dof();
        check_len("q", n, q.len())?;
        check_len("mass matrix rows", n + 6, m.nrows())?;
        check_len("mass matrix columns", n + 6, m.ncols())?;
        ws.check(self)?;
        m.fill(0.0);
        self.composite_inertias(ws, q);
        // Base block: the 6×6 composite inertia of the whole robot, columns = unit base motions.
        for c in 0..6 {
            let mut e = Motion::ZERO;
            if c < 3 {
                e.lin[c] = 1.0;
            } else {
                e.ang[c - 3] = 1.0;
            }
            let f = ws.ic[0].apply(&e);
            for r in 0..3 {
                m[(r, c)] = f.lin[r];
                m[(r + 3, c)] = f.ang[r];
            }
        }
        for j in 0..n {
            let b = j + 1;
            let mut f = ws.ic[b].apply(&self.joint_motion(j));
            m[(6 + j, 6 + j)] = self.joint_motion(j).dot(&f);
            let mut k = b;
            while let Some(p) = self.parent_body(k) {
                f = ws.x[k].force_to_parent(&f);
                k = p;
                if p == 0 {
                    break;
                }
                let v = self.joint_motion(k - 1).dot(&f);
                m[(6 + k - 1, 6 + j)] = v;
                m[(6 + j, 6 + k - 1)] = v;
            }
            for r in 0..3 {
                m[(r, 6 + j)] = f.lin[r];
                m[(r + 3, 6 + j)] = f.ang[r];
                m[(6 + j, r)] = f.lin[r];
                m[(6 + j, r + 3)] = f.ang[r];
            }
        }
        Ok(())
    }

    /// True if body `a` is body `b` or one of its ancestors.
    pub fn is_ancestor(&self, a: usize, b: usize) -> bool {
        let mut k = b;
        loop {
            if k == a {
                return true;
            }
            match self.parent_body(k) {
                Some(p) => k = p,
                None => return false,
            }
        }
    }

    /// Placement of every body in the root frame for configuration `q` (index = body; 0 = root).
    pub fn body_placements(&self, q: &[f64]) -> Result<Vec<Transform>, DynamicsError> {
        check_len("q", self.dof(), q.len())?;
        let mut out = vec![Transform::identity(); self.dof() + 1];
        for (j, jt) in self.joints.iter().enumerate() {
            out[j + 1] = out[jt.parent_body].compose(&jt.placement(q[j]));
        }
        Ok(out)
    }

    /// Placement of the named frame `id` in the root frame for configuration `q` (Pinocchio's
    /// `updateFramePlacement` on a fixed base): the frame's chain to the root only, no allocation.
    pub fn frame_placement(&self, id: FrameId, q: &[f64]) -> Result<Transform, DynamicsError> {
        check_len("q", self.dof(), q.len())?;
        let frame = self
            .frames
            .get(id.0)
            .ok_or_else(|| DynamicsError::BadInput {
                what: "frame id".into(),
                value: format!("{} (the model has {} frames)", id.0, self.frames.len()),
            })?;
        let mut x = frame.placement;
        let mut body = frame.body;
        while body > 0 {
            let j = body - 1;
            x = self.joints[j].placement(q[j]).compose(&x);
            body = self.joints[j].parent_body;
        }
        Ok(x)
    }
}

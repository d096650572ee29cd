//! Spatial (6-D) algebra for rigid-body dynamics: motion and force vectors, rigid transforms and
//! spatial inertias, written on nalgebra's fixed-size 3-vectors and 3×3 matrices.
//!
//! It is **not** a general Lie-group library: only what RNEA and CRBA need. Everything here is
//! `Copy`, lives on the stack and never allocates (hand-written instead of 6×6 matrices because the
//! 3+3 split needs about a third of the flops, which matters for the ≤ 5 µs RNEA budget).
//!
//! Conventions (the same as Pinocchio's, except that the angular part is stored in its own field):
//! - A [`Motion`] `(ang, lin)` is a twist: angular velocity and the linear velocity **of the point at
//!   the frame origin**, both expressed in that frame.
//! - A [`Force`] `(ang, lin)` is a wrench: moment **about the frame origin** and force, both expressed
//!   in that frame.
//! - A [`Transform`] `(rot, pos)` is the placement of a child frame in a parent frame:
//!   `x_parent = rot · x_child + pos`.

use nalgebra::{Matrix3, Vector3};

/// Skew-symmetric matrix `[v]×` such that `[v]× · w = v × w`.
#[inline]
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Rotation matrix from URDF roll-pitch-yaw angles [rad]: `R = Rz(yaw) · Ry(pitch) · Rx(roll)`.
pub fn rpy_to_matrix(rpy: [f64; 3]) -> Matrix3<f64> {
    *nalgebra::Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]).matrix()
}

/// Rotation by `angle_rad` about the **unit** axis `axis` (Rodrigues' formula).
#[inline]
pub fn axis_angle(axis: &Vector3<f64>, angle_rad: f64) -> Matrix3<f64> {
    let (s, c) = angle_rad.sin_cos();
    axis_angle_sin_cos(axis, s, c)
}

/// [`axis_angle`] from the sine `s` and cosine `c` of the angle.
#[inline]
pub fn axis_angle_sin_cos(axis: &Vector3<f64>, s: f64, c: f64) -> Matrix3<f64> {
    let t = 1.0 - c;
    let (x, y, z) = (axis.x, axis.y, axis.z);
    Matrix3::new(
        t * x * x + c,
        t * x * y - s * z,
        t * x * z + s * y,
        t * x * y + s * z,
        t * y * y + c,
        t * y * z - s * x,
        t * x * z - s * y,
        t * y * z + s * x,
        t * z * z + c,
    )
}

/// A spatial motion vector (twist or spatial acceleration), see the module doc for the convention.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Angular part [rad/s or rad/s²].
    pub ang: Vector3<f64>,
    /// Linear part at the frame origin [m/s or m/s²].
    pub lin: Vector3<f64>,
}

impl Motion {
    /// The zero motion.
    pub const ZERO: Motion = Motion {
        ang: Vector3::new(0.0, 0.0, 0.0),
        lin: Vector3::new(0.0, 0.0, 0.0),
    };

    /// Builds a motion from its angular and linear parts.
    #[inline]
    pub fn new(ang: Vector3<f64>, lin: Vector3<f64>) -> Self {
        Self { ang, lin }
    }

    /// Motion cross product `self × m` (the derivative of `m` moving with velocity `self`).
    #[inline]
    pub fn cross_motion(&self, m: &Motion) -> Motion {
        Motion {
            ang: self.ang.cross(&m.ang),
            lin: self.ang.cross(&m.lin) + self.lin.cross(&m.ang),
        }
    }

    /// Force cross product `self ×* f`.
    #[inline]
    pub fn cross_force(&self, f: &Force) -> Force {
        Force {
            ang: self.ang.cross(&f.ang) + self.lin.cross(&f.lin),
            lin: self.ang.cross(&f.lin),
        }
    }

    /// Scaled sum `self + k·m`.
    #[inline]
    pub fn add_scaled(&self, m: &Motion, k: f64) -> Motion {
        Motion {
            ang: self.ang + m.ang * k,
            lin: self.lin + m.lin * k,
        }
    }

    /// Power pairing `self · f` (a scalar).
    #[inline]
    pub fn dot(&self, f: &Force) -> f64 {
        self.ang.dot(&f.ang) + self.lin.dot(&f.lin)
    }
}

/// A spatial force vector (wrench), see the module doc for the convention.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Force {
    /// Moment about the frame origin [N·m].
    pub ang: Vector3<f64>,
    /// Force [N].
    pub lin: Vector3<f64>,
}

impl Force {
    /// The zero wrench.
    pub const ZERO: Force = Force {
        ang: Vector3::new(0.0, 0.0, 0.0),
        lin: Vector3::new(0.0, 0.0, 0.0),
    };

    /// Builds a wrench from its moment and force.
    #[inline]
    pub fn new(ang: Vector3<f64>, lin: Vector3<f64>) -> Self {
        Self { ang, lin }
    }
}

impl std::ops::Add for Force {
    type Output = Force;
    #[inline]
    fn add(self, o: Force) -> Force {
        Force {
            ang: self.ang + o.ang,
            lin: self.lin + o.lin,
        }
    }
}

impl std::ops::Sub for Force {
    type Output = Force;
    #[inline]
    fn sub(self, o: Force) -> Force {
        Force {
            ang: self.ang - o.ang,
            lin: self.lin - o.lin,
        }
    }
}

impl std::ops::AddAssign for Force {
    #[inline]
    fn add_assign(&mut self, o: Force) {
        self.ang += o.ang;
        self.lin += o.lin;
    }
}

impl std::ops::Add for Motion {
    type Output = Motion;
    #[inline]
    fn add(self, o: Motion) -> Motion {
        Motion {
            ang: self.ang + o.ang,
            lin: self.lin + o.lin,
        }
    }
}

/// Placement of a child frame in a parent frame: `x_parent = rot · x_child + pos`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    /// Orientation of the child frame in the parent frame.
    pub rot: Matrix3<f64>,
    /// Position of the child origin in the parent frame [m].
    pub pos: Vector3<f64>,
}

impl Transform {
    /// The identity placement.
    pub fn identity() -> Self {
        Self {
            rot: Matrix3::identity(),
            pos: Vector3::zeros(),
        }
    }

    /// Builds a placement from a URDF `<origin xyz rpy>`.
    pub fn from_xyz_rpy(xyz: [f64; 3], rpy: [f64; 3]) -> Self {
        Self {
            rot: rpy_to_matrix(rpy),
            pos: Vector3::new(xyz[0], xyz[1], xyz[2]),
        }
    }

    /// Composition `self ∘ child`: the placement of `child`'s frame in `self`'s parent frame.
    #[inline]
    pub fn compose(&self, child: &Transform) -> Transform {
        Transform {
            rot: self.rot * child.rot,
            pos: self.rot * child.pos + self.pos,
        }
    }

    /// The inverse placement (parent in child).
    #[inline]
    pub fn inverse(&self) -> Transform {
        let rt = self.rot.transpose();
        Transform {
            rot: rt,
            pos: -(rt * self.pos),
        }
    }

    /// Expresses a parent-frame motion in the child frame.
    #[inline]
    pub fn motion_to_child(&self, m: &Motion) -> Motion {
        let rt = self.rot.transpose();
        Motion {
            ang: rt * m.ang,
            lin: rt * (m.lin + m.ang.cross(&self.pos)),
        }
    }

    /// Expresses a child-frame motion in the parent frame.
    #[inline]
    pub fn motion_to_parent(&self, m: &Motion) -> Motion {
        let ang = self.rot * m.ang;
        Motion {
            ang,
            lin: self.rot * m.lin + self.pos.cross(&ang),
        }
    }

    /// Expresses a child-frame wrench in the parent frame (moment moved to the parent origin).
    #[inline]
    pub fn force_to_parent(&self, f: &Force) -> Force {
        let lin = self.rot * f.lin;
        Force {
            ang: self.rot * f.ang + self.pos.cross(&lin),
            lin,
        }
    }

    /// Expresses a parent-frame wrench in the child frame (moment moved to the child origin).
    #[inline]
    pub fn force_to_child(&self, f: &Force) -> Force {
        let rt = self.rot.transpose();
        Force {
            ang: rt * (f.ang - self.pos.cross(&f.lin)),
            lin: rt * f.lin,
        }
    }
}

/// Spatial inertia of a rigid body in some frame: mass, first moment of mass and rotational inertia
/// **about the frame origin**. Sums of these are the inertia of the union of the bodies.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpatialInertia {
    /// Mass [kg].
    pub mass_kg: f64,
    /// First moment of mass `m·c` [kg·m] (c = centre of mass in this frame).
    pub first_moment_kg_m: Vector3<f64>,
    /// Rotational inertia about the frame origin, in this frame [kg·m²].
    pub rot_inertia_kg_m2: Matrix3<f64>,
}

impl SpatialInertia {
    /// The inertia of nothing.
    pub fn zero() -> Self {
        Self {
            mass_kg: 0.0,
            first_moment_kg_m: Vector3::zeros(),
            rot_inertia_kg_m2: Matrix3::zeros(),
        }
    }

    /// From mass, centre of mass `com_m` and rotational inertia about the centre of mass (all in
    /// this frame), by the parallel-axis theorem.
    pub fn from_com(mass_kg: f64, com_m: Vector3<f64>, inertia_at_com_kg_m2: Matrix3<f64>) -> Self {
        let cx = skew(&com_m);
        Self {
            mass_kg,
            first_moment_kg_m: com_m * mass_kg,
            rot_inertia_kg_m2: inertia_at_com_kg_m2 - cx * cx * mass_kg,
        }
    }

    /// Centre of mass in this frame [m] (zero for a massless body).
    pub fn com_m(&self) -> Vector3<f64> {
        if self.mass_kg > 0.0 {
            self.first_moment_kg_m / self.mass_kg
        } else {
            Vector3::zeros()
        }
    }

    /// Rotational inertia about the centre of mass [kg·m²].
    pub fn inertia_at_com_kg_m2(&self) -> Matrix3<f64> {
        let c = self.com_m();
        let cx = skew(&c);
        self.rot_inertia_kg_m2 + cx * cx * self.mass_kg
    }

    /// Momentum `I · v` of the body moving with twist `v`.
    #[inline]
    pub fn apply(&self, v: &Motion) -> Force {
        let h = &self.first_moment_kg_m;
        Force {
            ang: self.rot_inertia_kg_m2 * v.ang + h.cross(&v.lin),
            lin: v.lin * self.mass_kg - h.cross(&v.ang),
        }
    }

    /// The same inertia expressed in the parent frame of `x` (x = placement of this frame there).
    pub fn to_parent(&self, x: &Transform) -> SpatialInertia {
        let m = self.mass_kg;
        let hr = x.rot * self.first_moment_kg_m;
        let p = x.pos;
        let px = skew(&p);
        let hx = skew(&hr);
        let i_rot = x.rot * self.rot_inertia_kg_m2 * x.rot.transpose();
        SpatialInertia {
            mass_kg: m,
            first_moment_kg_m: hr + p * m,
            rot_inertia_kg_m2: i_rot - (hx * px + px * hx) - px * px * m,
        }
    }
}

impl std::ops::Add for SpatialInertia {
    type Output = SpatialInertia;
    fn add(self, o: SpatialInertia) -> SpatialInertia {
        SpatialInertia {
            mass_kg: self.mass_kg + o.mass_kg,
            first_moment_kg_m: self.first_moment_kg_m + o.first_moment_kg_m,
            rot_inertia_kg_m2: self.rot_inertia_kg_m2 + o.rot_inertia_kg_m2,
        }
    }
}

impl std::ops::AddAssign for SpatialInertia {
    fn add_assign(&mut self, o: SpatialInertia) {
        *self = *self + o;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_transform() -> Transform {
        Transform::from_xyz_rpy([0.1, -0.2, 0.3], [0.4, -0.5, 0.6])
    }

    #[test]
    fn rpy_matches_urdf_convention() {
        // URDF: R = Rz(y)·Ry(p)·Rx(r).
        let (r, p, y) = (0.3, -0.7, 1.1);
        let expect = axis_angle(&Vector3::z(), y)
            * axis_angle(&Vector3::y(), p)
            * axis_angle(&Vector3::x(), r);
        assert!((rpy_to_matrix([r, p, y]) - expect).norm() < 1e-14);
    }

    #[test]
    fn motion_and_force_transforms_preserve_power() {
        let x = sample_transform();
        let v = Motion::new(Vector3::new(0.3, 1.0, -2.0), Vector3::new(0.5, -0.1, 0.7));
        let f = Force::new(Vector3::new(-1.0, 0.2, 0.4), Vector3::new(3.0, -2.0, 1.0));
        // power is frame independent
        let p_child = v.dot(&f);
        let p_parent = x.motion_to_parent(&v).dot(&x.force_to_parent(&f));
        assert!((p_child - p_parent).abs() < 1e-12);
        // round trips
        let v2 = x.motion_to_child(&x.motion_to_parent(&v));
        assert!((v2.ang - v.ang).norm() + (v2.lin - v.lin).norm() < 1e-12);
        let f2 = x.force_to_child(&x.force_to_parent(&f));
        assert!((f2.ang - f.ang).norm() + (f2.lin - f.lin).norm() < 1e-12);
    }

    #[test]
    fn inertia_to_parent_matches_parallel_axis() {
        let x = sample_transform();
        let ic = Matrix3::new(
            0.02, 0.001, -0.002, 0.001, 0.03, 0.0005, -0.002, 0.0005, 0.01,
        );
        let com = Vector3::new(0.01, 0.02, -0.1);
        let i = SpatialInertia::from_com(2.5, com, ic);
        let ip = i.to_parent(&x);
        // direct construction in the parent frame
        let expect =
            SpatialInertia::from_com(2.5, x.rot * com + x.pos, x.rot * ic * x.rot.transpose());
        assert!((ip.rot_inertia_kg_m2 - expect.rot_inertia_kg_m2).norm() < 1e-12);
        assert!((ip.first_moment_kg_m - expect.first_moment_kg_m).norm() < 1e-12);
        // momentum transforms as a force
        let v = Motion::new(Vector3::new(0.3, 1.0, -2.0), Vector3::new(0.5, -0.1, 0.7));
        let h_child = i.apply(&v);
        let h_parent = ip.apply(&x.motion_to_parent(&v));
        let h_moved = x.force_to_parent(&h_child);
        assert!((h_parent.ang - h_moved.ang).norm() + (h_parent.lin - h_moved.lin).norm() < 1e-12);
    }
}

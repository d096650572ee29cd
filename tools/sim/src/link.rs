//! Link dynamics seen by the simulated joint: inertia and gravity torque as functions of the joint angle.
//!
//! What it is: the [`LinkDynamics`] trait (other joints held fixed, so only I_L(s), g(s) and an optional
//! velocity term), the analytic [`Pendulum`], the URDF single-joint view and the factory [`link_from_model`] for the preset's
//! `[plant.link]` table.
//!
//! The URDF-backed link is [`frictionless_dynamics::SingleJoint`] (fixed base, other joints held still:
//! constant I_L, g(s) = α·cos s + β·sin s), built from `kind = "urdf"`.
//!
//! What it is not: a rigid-body library (that is [`frictionless_dynamics`]).

use crate::params::{LinkModel, ParamError};

/// Single-joint link dynamics, joint-side units: I_L(s)·s̈ + c(s, ṡ) + g(s) = τ.
pub trait LinkDynamics: Send + Sync {
    /// Link inertia about the joint axis I_L(s) [kg·m²].
    fn inertia_kgm2(&self, s_rad: f64) -> f64;
    /// Gravity torque g(s) [Nm]: the joint torque that holds the link still at `s_rad`.
    fn gravity_nm(&self, s_rad: f64) -> f64;
    /// Velocity-dependent torque c(s, ṡ) [Nm] (0 for a single joint whose own angle does not change
    /// its inertia, which is the case with the other joints fixed).
    fn velocity_torque_nm(&self, _s_rad: f64, _s_dot_rad_s: f64) -> f64 {
        0.0
    }
    /// The link in closed form, if it has one: constant I_L, no velocity torque and
    /// g(s) = a·sin s + b·cos s. The simulator's fast path reads it once per 1 kHz sample and then
    /// needs no call into the link (and no `sin`) per physics step; `None` (the default) makes it call
    /// [`LinkDynamics::inertia_kgm2`] / [`LinkDynamics::gravity_nm`] every step.
    fn closed_form(&self) -> Option<LinkClosedForm> {
        None
    }
}

/// A link whose dynamics are I_L·s̈ + a·sin s + b·cos s = τ (see [`LinkDynamics::closed_form`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkClosedForm {
    /// Constant link inertia I_L [kg·m²].
    pub inertia_kgm2: f64,
    /// Gravity coefficient a of sin s [Nm].
    pub gravity_sin_nm: f64,
    /// Gravity coefficient b of cos s [Nm].
    pub gravity_cos_nm: f64,
}

impl<T: LinkDynamics + ?Sized> LinkDynamics for Box<T> {
    #[inline]
    fn inertia_kgm2(&self, s_rad: f64) -> f64 {
        (**self).inertia_kgm2(s_rad)
    }
    #[inline]
    fn gravity_nm(&self, s_rad: f64) -> f64 {
        (**self).gravity_nm(s_rad)
    }
    #[inline]
    fn velocity_torque_nm(&self, s_rad: f64, s_dot_rad_s: f64) -> f64 {
        (**self).velocity_torque_nm(s_rad, s_dot_rad_s)
    }
    #[inline]
    fn closed_form(&self) -> Option<LinkClosedForm> {
        (**self).closed_form()
    }
}

/// Analytic pendulum: constant I_L, g(s) = A·sin(s + phase).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pendulum {
    /// Inertia about the joint [kg·m²].
    pub inertia_kgm2: f64,
    /// Gravity amplitude A = m·g·l [Nm].
    pub gravity_amplitude_nm: f64,
    /// Phase [rad] (0: hanging at s = 0).
    pub gravity_phase_rad: f64,
}

impl LinkDynamics for Pendulum {
    #[inline]
    fn inertia_kgm2(&self, _s_rad: f64) -> f64 {
        self.inertia_kgm2
    }
    #[inline]
    fn gravity_nm(&self, s_rad: f64) -> f64 {
        self.gravity_amplitude_nm * (s_rad + self.gravity_phase_rad).sin()
    }
    fn closed_form(&self) -> Option<LinkClosedForm> {
        // A·sin(s + φ) = A·cos φ·sin s + A·sin φ·cos s
        let (sp, cp) = self.gravity_phase_rad.sin_cos();
        Some(LinkClosedForm {
            inertia_kgm2: self.inertia_kgm2,
            gravity_sin_nm: self.gravity_amplitude_nm * cp,
            gravity_cos_nm: self.gravity_amplitude_nm * sp,
        })
    }
}

/// A borrowed link model is a link model (so several controllers can share one preset's link).
impl<T: LinkDynamics + ?Sized> LinkDynamics for &T {
    #[inline]
    fn inertia_kgm2(&self, s_rad: f64) -> f64 {
        (**self).inertia_kgm2(s_rad)
    }
    #[inline]
    fn gravity_nm(&self, s_rad: f64) -> f64 {
        (**self).gravity_nm(s_rad)
    }
    #[inline]
    fn velocity_torque_nm(&self, s_rad: f64, s_dot_rad_s: f64) -> f64 {
        (**self).velocity_torque_nm(s_rad, s_dot_rad_s)
    }
}

impl LinkDynamics for frictionless_dynamics::SingleJoint {
    #[inline]
    fn inertia_kgm2(&self, _s_rad: f64) -> f64 {
        self.inertia_kg_m2()
    }
    #[inline]
    fn gravity_nm(&self, s_rad: f64) -> f64 {
        frictionless_dynamics::SingleJoint::gravity_nm(self, s_rad)
    }
    fn closed_form(&self) -> Option<LinkClosedForm> {
        // revolute: g(s) = α·cos s + β·sin s; a prismatic joint is not an angle, no closed form
        match self.kind {
            frictionless_dynamics::JointKind::Revolute => Some(LinkClosedForm {
                inertia_kgm2: self.inertia,
                gravity_sin_nm: self.beta,
                gravity_cos_nm: self.alpha,
            }),
            frictionless_dynamics::JointKind::Prismatic => None,
        }
    }
}

/// Builds the link dynamics described by a preset's `[plant.link]` table.
pub fn link_from_model(model: &LinkModel) -> Result<Box<dyn LinkDynamics>, ParamError> {
    match model {
        &LinkModel::Pendulum {
            inertia_kgm2,
            gravity_amplitude_nm,
            gravity_phase_rad,
        } => Ok(Box::new(Pendulum {
            inertia_kgm2,
            gravity_amplitude_nm,
            gravity_phase_rad,
        })),
        LinkModel::Urdf {
            urdf,
            joint,
            other_joints_rad,
            gravity_m_s2,
        } => {
            let err = |e: frictionless_dynamics::DynamicsError| ParamError::Link(e.to_string());
            let robot = if urdf == "virtual_leg" {
                frictionless_dynamics::virtual_leg().map_err(err)?
            } else {
                frictionless_dynamics::Robot::from_urdf_file(urdf).map_err(err)?
            };
            let robot = match *gravity_m_s2 {
                Some(g) => robot.with_gravity_m_s2(g).map_err(err)?,
                None => robot,
            };
            let mut q = vec![0.0; robot.dof()];
            for (name, &v) in other_joints_rad {
                q[robot.joint_index(name).map_err(err)?] = v;
            }
            let view = robot.single_joint_view(joint, &q).map_err(err)?;
            if view.inertia.is_nan() || view.inertia <= 0.0 {
                return Err(ParamError::Link(format!(
                    "joint {joint} of {urdf} has link inertia {} (must be > 0)",
                    view.inertia
                )));
            }
            Ok(Box::new(view))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pendulum_gravity_is_zero_hanging_and_peaks_horizontal() {
        let p = Pendulum {
            inertia_kgm2: 0.5,
            gravity_amplitude_nm: 16.6,
            gravity_phase_rad: 0.0,
        };
        assert!(p.gravity_nm(0.0).abs() < 1e-12);
        assert!((p.gravity_nm(-std::f64::consts::FRAC_PI_2) + 16.6).abs() < 1e-9);
        assert_eq!(p.inertia_kgm2(1.0), 0.5);
    }
}

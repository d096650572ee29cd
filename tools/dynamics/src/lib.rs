//! # `frictionless-dynamics`: URDF rigid-body dynamics
//!
//! Crate table: `tools/dynamics`; depends on nalgebra, urdf-rs, quick-xml (a pre-pass that drops the
//! geometry dynamics never reads) and `frictionless` (its [`frictionless::regular_file`] reads only);
//! used by `frictionless-sim` (the link model of the virtual joint) and `frictl` (`frictl dynamics`,
//! `frictl experiment`).
//!
//! What this crate **is**: a URDF loader that builds a kinematic tree with fixed joints lumped and optional
//! joint locking ([`Robot`], [`Reduction`]), and allocation-free algorithms on it: fixed- and
//! floating-base RNEA with external wrenches, CRBA mass matrix, gravity and bias torques
//! ([`Workspace`]), fixed-base forward dynamics by the articulated-body algorithm ([`aba`]), plus the single-joint link-side view used by the virtual joint simulator
//! ([`SingleJoint`]). Conventions follow Pinocchio (see [`algorithms`]); results are cross-checked
//! against Pinocchio on iCub 3, ergoCub and the 68 URDFs of example-robot-data 6.0.0 that Pinocchio
//! loads (arms, quadrupeds, humanoids, hands, mobile manipulators; worst difference 7e-13 N·m) in
//! `tools/dynamics/tests/dynamics_pinocchio.rs`.
//!
//! What it is **not**: an integrator, contact solving, geometry or visualisation.
//!
//! The project's own model is `config/urdf/virtual_leg.urdf` ([`DEFAULT_URDF`]).
//!
//! ## Example: URDF → inverse dynamics
//! ```
//! use frictionless_dynamics::{Robot, Workspace};
//!
//! let robot: Robot = frictionless_dynamics::virtual_leg()?; // or Robot::from_urdf_file("robot.urdf")
//! let n = robot.dof();
//! let knee = robot.joint_index("l_knee")?;
//! let mut ws = Workspace::new(&robot);
//! let mut q = vec![0.0; n];
//! q[knee] = -0.8; // rad
//! let (qd, qdd) = (vec![0.0; n], vec![0.0; n]);
//!
//! // At rest, RNEA is the gravity torque; allocation-free once the workspace exists.
//! let mut tau = vec![0.0; n];
//! robot.rnea(&mut ws, &q, &qd, &qdd, &mut tau)?;
//! let mut g = vec![0.0; n];
//! robot.gravity_torques(&mut ws, &q, &mut g)?;
//! assert!((tau[knee] - g[knee]).abs() < 1e-12);
//! assert!(tau[knee].abs() > 0.1, "a bent knee holds its shank against gravity");
//! # Ok::<(), frictionless_dynamics::DynamicsError>(())
//! ```

#![warn(missing_docs)]

pub mod aba;
pub mod algorithms;
pub mod error;
pub mod robot;
pub mod single_joint;
pub mod spatial;

pub use algorithms::{BaseState, ExternalWrench, GRAVITY_M_S2, Workspace, gravity_world};
pub use error::DynamicsError;
pub use robot::{Frame, FrameId, Joint, JointKind, Reduction, Robot};
pub use single_joint::{SingleJoint, SingleJointTable};
pub use spatial::{Force, Motion, SpatialInertia, Transform};

/// The project's own humanoid leg + torso URDF (15 DoF), embedded so nothing needs files or pip.
pub const DEFAULT_URDF: &str = include_str!("../../../config/urdf/virtual_leg.urdf");

/// Path of the project's own URDF relative to the repository root (what `--urdf` defaults to).
pub const DEFAULT_URDF_PATH: &str = "config/urdf/virtual_leg.urdf";

/// Loads the project's own leg model ([`DEFAULT_URDF`]).
pub fn virtual_leg() -> Result<Robot, DynamicsError> {
    Robot::from_urdf_str(DEFAULT_URDF, DEFAULT_URDF_PATH)
}

//! The plants a trial runs against, as the controller and frictiond's config need them.
//!
//! What this module **is**: [`JointSetup`] (a single-joint plant preset's link model, gear ratio and
//! k_t — the controller's M and h come from exactly the link model the plant simulates),
//! [`LegSetup`] (the coupled leg's parameters and its nominal URDF model, the one the whole-leg
//! controller [`super::controller::LegComputedTorque`] uses for M(q) and h(q, q̇)) and [`Rig`], the
//! choice between them that [`super::run::run_trial_on`] takes.
//!
//! What it is **not**: no trial loop (see [`super::run`]), no suites.

use frictionless_sim::leg::LEG_PRESET_TOML;
use frictionless_sim::link::{LinkDynamics, link_from_model};
use frictionless_sim::params::load_table;
use frictionless_sim::{LegParams, PlantParams};

use super::ExperimentError;
use super::session::PRESETS;

/// A plant preset as the controller and the daemon config need it.
pub struct JointSetup {
    /// Preset name (`knee`, `ankle_roll`).
    pub preset: String,
    /// The plant parameters (joint name, signed r, k_t, range, initial pose, link model).
    pub params: PlantParams,
    /// The link model the plant simulates (M = I_L, h = g).
    pub link: Box<dyn LinkDynamics>,
}

impl JointSetup {
    /// Loads `preset` with `--set` overrides `sets` (the same ones the plant gets).
    pub fn load(preset: &str, sets: &[String]) -> Result<Self, ExperimentError> {
        let table = load_table(preset, None, sets)?;
        let params = PlantParams::from_table(&table)?;
        let link = link_from_model(&params.link)?;
        Ok(Self {
            preset: preset.to_owned(),
            params,
            link,
        })
    }

    /// Both presets in payload order ([`PRESETS`]).
    pub fn both(sets: &[String]) -> Result<[JointSetup; 2], ExperimentError> {
        frictionless_sim::params::check_set_joints(sets, &PRESETS)?;
        Ok([Self::load(PRESETS[0], sets)?, Self::load(PRESETS[1], sets)?])
    }
}

/// The plant a trial runs against, and with it the controller: each single-joint preset with its own
/// link model, or the coupled leg with the whole-leg computed torque on its nominal URDF.
#[derive(Clone, Copy)]
pub enum Rig<'a> {
    /// The two independent single-joint presets ([`PRESETS`]: knee = 0, ankle_roll = 1); each
    /// planned joint gets [`ComputedTorque`] on its preset's link model.
    Pair(&'a [JointSetup; 2]),
    /// The six-joint leg (`--preset leg`); every joint must be planned (one trial controls the whole
    /// leg with [`LegComputedTorque`]).
    Leg(&'a LegSetup),
}

impl Rig<'_> {
    /// Joints of the plant.
    pub fn dof(&self) -> usize {
        match self {
            Rig::Pair(s) => s.len(),
            Rig::Leg(l) => l.dof(),
        }
    }

    /// Drive parameters of joint `i` (joint name, signed r, k_t, initial pose, J_eq).
    pub fn params(&self, i: usize) -> &PlantParams {
        match self {
            Rig::Pair(s) => &s[i].params,
            Rig::Leg(l) => &l.params.joints[i],
        }
    }

    /// The plant server's `--preset` argument.
    pub(crate) fn preset_arg(&self) -> String {
        match self {
            Rig::Pair(_) => PRESETS.join(","),
            Rig::Leg(_) => "leg".to_owned(),
        }
    }
}

/// The leg as the controller and frictiond's config need it.
#[derive(Clone, Debug)]
pub struct LegSetup {
    /// The leg's drives (payload order) and URDF.
    pub params: LegParams,
    /// The nominal URDF model (kept joints movable, the rest locked): the controller's M and h.
    pub robot: frictionless_dynamics::Robot,
}

impl LegSetup {
    /// The built-in leg preset with `sets` (`JOINT:plant.KEY=VALUE` or `plant.KEY=VALUE`), the same
    /// overrides the plant gets.
    pub fn load(sets: &[String]) -> Result<Self, ExperimentError> {
        let params = LegParams::from_toml_str(LEG_PRESET_TOML, "<preset leg>", sets)?;
        let robot = params.nominal_robot()?;
        Ok(Self { params, robot })
    }

    /// Joints of the leg.
    pub fn dof(&self) -> usize {
        self.params.joints.len()
    }

    /// Payload index of joint `name`.
    pub fn index(&self, name: &str) -> Result<usize, ExperimentError> {
        self.params
            .joints
            .iter()
            .position(|p| p.joint == name)
            .ok_or_else(|| ExperimentError::LegJoint(name.to_owned()))
    }
}

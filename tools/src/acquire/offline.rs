//! Offline acquisition: the excitation protocol played on a fresh simulated plant.
//!
//! What it is: [`run_offline`], the one place that builds the plant from [`PlantParams`] and a seed,
//! gives the controllers the joint's nominal model ([`ControllerModel::nominal`]) and runs
//! [`crate::acquire::protocol::run`] over a [`SimJoint`] — what `frictl acquire` does without
//! `--live-shm`, and what the protocol, label and training tests do in-process.
//!
//! What it is not: file output (the caller's `sink` decides; `frictl acquire` writes
//! [`crate::acquire::log::CsvLog`]) or a live plant (that is [`crate::serve::shm::LiveJoint`]).

use crate::acquire::config::ProtocolConfig;
use crate::acquire::protocol::{
    AcquireError, Block, ControllerModel, LogRow, RunSummary, SimJoint,
};
use crate::sim::{ParamError, Plant, PlantParams};

/// Why an offline run failed.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// The plant parameters do not build a plant (link model, sensor or friction parameters).
    #[error("cannot build the simulated plant: {0}")]
    Plant(#[from] ParamError),
    /// The run itself failed (in practice: the sink).
    #[error(transparent)]
    Run(#[from] AcquireError),
}

/// What an offline run reports besides the rows it handed to the sink.
#[derive(Clone, Debug, PartialEq)]
pub struct OfflineRun {
    /// The protocol's summary (samples, chunks, guard latches, duration).
    pub summary: RunSummary,
    /// The plant's initial temperature, drawn from the seed [°C].
    pub initial_temperature_c: f64,
}

/// Plays `blocks` (normally [`crate::acquire::schedule`]`(protocol)`) on a new simulated plant built
/// from `params` and `seed` (initial temperature, noise), with no external torque and the controllers
/// using the joint's nominal model. Every 1 kHz row (with the simulator's truth) goes to `sink` in
/// order.
///
/// # Errors
/// [`OfflineError::Plant`] if `params` do not build a plant, [`OfflineError::Run`] if the sink fails.
pub fn run_offline(
    params: &PlantParams,
    protocol: &ProtocolConfig,
    blocks: &[Block],
    seed: u64,
    sink: &mut dyn FnMut(&LogRow) -> Result<(), AcquireError>,
) -> Result<OfflineRun, OfflineError> {
    let link = crate::sim::link::link_from_model(&params.link)?;
    let model = ControllerModel::nominal(params, link.as_ref());
    let plant = Plant::from_params(params.clone(), seed)?;
    let initial_temperature_c = plant.state().temperature_c;
    let mut joint = SimJoint {
        plant,
        tau_ext_nm: 0.0,
    };
    let summary = crate::acquire::protocol::run(&mut joint, &model, protocol, blocks, sink)?;
    Ok(OfflineRun {
        summary,
        initial_temperature_c,
    })
}

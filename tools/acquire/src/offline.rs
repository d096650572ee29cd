//! Offline acquisition: the excitation protocol played on a fresh simulated plant.
//!
//! What it is: [`run_offline`], the one place that builds the plant from [`PlantParams`] and a seed,
//! gives the controllers the joint's nominal model ([`ControllerModel::nominal`]) and runs
//! [`crate::protocol::run`] over a [`SimJoint`] — what `frictl acquire` does without
//! `--live-shm`, and what the protocol, label and training tests do in-process — plus the in-memory
//! hand-over to the label pipeline ([`raw_log`], [`log_meta`]: what `frictl preprocess` reads from the
//! CSV and sidecar `frictl acquire` writes, without the file).
//!
//! What it is not: file output (the caller's `sink` decides; `frictl acquire` writes
//! [`crate::log::CsvLog`]) or a live plant (that is `serve::shm::LiveJoint` in `frictl`).

use crate::config::ProtocolConfig;
use crate::protocol::{AcquireError, Block, ControllerModel, LogRow, RunSummary, SimJoint};
use frictionless_ident::preprocess::{LogMeta, RawLog};
use frictionless_sim::{ParamError, Plant, PlantParams};

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

/// Plays `blocks` (normally [`crate::schedule`]`(protocol)`) on a new simulated plant built
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
    let link = frictionless_sim::link::link_from_model(&params.link)?;
    let model = ControllerModel::nominal(params, link.as_ref());
    let plant = Plant::from_params(params.clone(), seed)?;
    let initial_temperature_c = plant.state().temperature_c;
    let mut joint = SimJoint {
        plant,
        tau_ext_nm: 0.0,
    };
    let summary = crate::protocol::run(&mut joint, &model, protocol, blocks, sink)?;
    Ok(OfflineRun {
        summary,
        initial_temperature_c,
    })
}

/// Every `stride`-th row of a run (1: the 1 kHz log; 2: a 500 Hz log; 0 counts as 1) as the label
/// pipeline's [`RawLog`], the columns of the `frictl acquire` CSV without its rounding. The truth
/// columns are present when every kept row carries the simulator's truth.
pub fn raw_log(rows: &[LogRow], stride: usize) -> RawLog {
    let rows: Vec<&LogRow> = rows.iter().step_by(stride.max(1)).collect();
    let col = |g: fn(&LogRow) -> f64| rows.iter().map(|r| g(r)).collect::<Vec<f64>>();
    let truth = |g: fn(&frictionless_sim::Truth) -> f64| {
        rows.iter()
            .map(|r| r.truth.as_ref().map(g))
            .collect::<Option<Vec<f64>>>()
    };
    RawLog {
        time_s: col(|r| r.meas.time_s),
        chunk: rows.iter().map(|r| r.chunk).collect(),
        active: rows.iter().map(|r| r.active).collect(),
        s_rad: col(|r| r.meas.s_rad),
        theta_motor_rad: col(|r| r.meas.theta_motor_rad),
        omega_motor_rad_s: col(|r| r.meas.omega_motor_rad_s),
        i_meas_a: col(|r| r.meas.i_meas_a),
        temperature_c: col(|r| r.meas.temperature_c),
        tau_f_true_nm: truth(|t| t.tau_f_nm),
        phi_ddot_rad_s2: truth(|t| t.phi_ddot_rad_s2),
    }
}

/// The label pipeline's [`LogMeta`] of a simulated joint (what the sidecar of an offline
/// `frictl acquire` run gives): joint name, signed r, k_t, the plant's link model and J_eq = r²·J_m.
pub fn log_meta(params: &PlantParams) -> LogMeta {
    LogMeta {
        joint: params.joint.clone(),
        gear_ratio_signed: params.gear_ratio_signed,
        kt_nm_per_a: params.kt_nm_per_a,
        plant_link: Some(params.link.clone()),
        j_eq_kgm2: Some(params.j_eq_kgm2()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedule;

    fn short_knee() -> (PlantParams, ProtocolConfig) {
        let sets: Vec<String> = [
            "protocol.n_starts=1",
            "protocol.sines.enabled=false",
            "protocol.ramps.slopes_a_per_s=[0.39]",
            "protocol.steps.enabled=false",
            "protocol.tracking.train.enabled=false",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let t = frictionless_sim::params::load_table("knee", None, &sets).unwrap();
        (
            PlantParams::from_table(&t).unwrap(),
            ProtocolConfig::from_table(&t).unwrap(),
        )
    }

    #[test]
    fn offline_run_hands_every_row_over_and_the_raw_log_keeps_them() {
        let (p, cfg) = short_knee();
        let blocks = schedule(&cfg);
        assert!(!blocks.is_empty());
        let mut rows = Vec::new();
        let run = run_offline(&p, &cfg, &blocks, 3, &mut |r| {
            rows.push(*r);
            Ok(())
        })
        .unwrap();
        assert_eq!(run.summary.samples as usize, rows.len());
        assert_eq!(run.summary.chunks as usize, blocks.len());
        assert_eq!(
            run.initial_temperature_c,
            Plant::from_params(p.clone(), 3)
                .unwrap()
                .state()
                .temperature_c
        );
        let full = raw_log(&rows, 1);
        assert_eq!(full.time_s.len(), rows.len());
        assert_eq!(full.i_meas_a[5], rows[5].meas.i_meas_a);
        assert_eq!(
            full.tau_f_true_nm.as_ref().unwrap()[7],
            rows[7].truth.unwrap().tau_f_nm
        );
        let half = raw_log(&rows, 2);
        assert_eq!(half.time_s.len(), rows.len().div_ceil(2));
        assert_eq!(half.s_rad[3], rows[6].meas.s_rad);
        // A row without truth (a live log) drops the truth columns instead of inventing them.
        rows[1].truth = None;
        let live = raw_log(&rows, 1);
        assert!(live.tau_f_true_nm.is_none() && live.phi_ddot_rad_s2.is_none());
        let m = log_meta(&p);
        assert_eq!(m.j_eq_kgm2, Some(p.j_eq_kgm2()));
        assert_eq!(m.gear_ratio_signed, p.gear_ratio_signed);
    }

    #[test]
    fn a_failing_sink_stops_the_run_with_its_error() {
        let (p, cfg) = short_knee();
        let mut n = 0;
        let e = run_offline(&p, &cfg, &schedule(&cfg), 0, &mut |_| {
            n += 1;
            if n == 10 {
                Err(AcquireError::Sink("disk full".into()))
            } else {
                Ok(())
            }
        })
        .unwrap_err();
        assert!(matches!(e, OfflineError::Run(AcquireError::Sink(_))), "{e}");
        assert_eq!(n, 10);
    }
}

//! On-policy recording (dataset aggregation, DAgger): closed-loop runs with compensation active,
//! written as acquisition logs that `frictl preprocess` labels like any other.
//!
//! What this module **is**: [`plans`] (the varied runs of one joint around a K_p: sines of other
//! amplitudes and frequencies than the experiments' test sine, gains from 0.7× to 2× the given one,
//! and disturbance pulses of both signs while holding), [`record`] (runs them through the real
//! processes — plant, `frictiond` with the model, this controller — via [`suite::run_grouped`]) and
//! [`write_raw_log`] (one joint's traces as the raw-log CSV `frictl acquire` writes: the columns of
//! `frictionless_acquire::log::COLUMNS` plus the plant's true friction `tau_f_true_nm` and motor
//! acceleration `phi_ddot`, one chunk per run, with a JSON sidecar carrying the plant parameters the label pipeline reads).
//!
//! What it is **not**: no labelling or training (that is `frictl preprocess` and `frictl train
//! --init`), no metrics (the per-run τ̂_F error is [`super::metrics::track`]'s).

use std::io::Write;
use std::path::Path;

use frictionless_acquire::log::{COLUMNS, SIM_COLUMNS};

use super::ExperimentError;
use super::controller::Reference;
use super::rig::JointSetup;
use super::run::{JointPlan, JointTrace, Pulse};
use super::session::{Binaries, FrictionModel};
use super::suite::{self, SuiteConfig, hold_rad, sine};

/// `mode` code of the closed-loop rows (`COLUMNS`' "3 closed-loop tracking").
pub const MODE_CLOSED_LOOP: u32 = 3;

/// Seconds of silence between runs in the written log, so `frictl preprocess --gap-s 1` (its
/// default) also splits chunks by time.
pub const RUN_GAP_S: f64 = 5.0;

/// [`Sidecar`](frictionless_acquire::log::Sidecar) `source` of closed-loop on-policy logs.
pub const SOURCE_CLOSED_LOOP: &str = "closed-loop-shm";

/// Rows left out on either side of a disturbance pulse (the zero-phase current filter and the
/// smoother spread its edges over a few milliseconds).
pub const PULSE_MARGIN_ROWS: usize = 50;

/// Rows to keep: those at least [`PULSE_MARGIN_ROWS`] away from every row with an external torque.
pub fn unlabelled_mask(tau_ext_nm: &[f64], n: usize) -> Vec<bool> {
    let mut keep = vec![true; n];
    for (k, &t) in tau_ext_nm.iter().enumerate().take(n) {
        if t != 0.0 {
            let lo = k.saturating_sub(PULSE_MARGIN_ROWS);
            let hi = (k + PULSE_MARGIN_ROWS + 1).min(n);
            keep[lo..hi].iter_mut().for_each(|v| *v = false);
        }
    }
    keep
}

/// One on-policy run of one joint.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RecordPlan {
    /// Joint index (0 = knee, 1 = ankle_roll).
    pub index: usize,
    /// Reference.
    pub reference: Reference,
    /// K_p [1/s²].
    pub kp_per_s2: f64,
    /// Disturbance pulse, if any.
    pub pulse: Option<Pulse>,
    /// Duration [s].
    pub duration_s: f64,
}

/// The on-policy sines, as (amplitude, frequency, K_p) factors on the experiments' test sine and the
/// given gain: none of them is the test sine.
pub const SINE_VARIATIONS: [(f64, f64, f64); 4] = [
    (0.6, 1.5, 1.0),
    (1.3, 0.7, 0.7),
    (1.0, 1.25, 1.5),
    (0.8, 0.9, 2.0),
];

/// One varied on-policy run of a joint ([`varied_runs`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VariedRun {
    /// Reference.
    pub reference: Reference,
    /// K_p [1/s²].
    pub kp_per_s2: f64,
    /// Disturbance pulse, if any.
    pub pulse: Option<Pulse>,
    /// Duration [s].
    pub duration_s: f64,
}

/// The varied runs of a joint around `kp_per_s2` (`runs` of them, at most 6): the four
/// [`SINE_VARIATIONS`] of its `test_sine` (`periods` periods each), then two holds at `hold_rad`
/// with `pulse`, positive at `kp_per_s2` and negative at 0.7× (at least 5 s, 1 s after the pulse),
/// interleaved so that a short list has both kinds. None of them is the experiments' test sine.
pub fn varied_runs(
    test_sine: Reference,
    hold_rad: f64,
    pulse: Pulse,
    kp_per_s2: f64,
    runs: usize,
    periods: f64,
) -> Vec<VariedRun> {
    let (centre_rad, amplitude_rad, freq_hz) = match test_sine {
        Reference::Sine {
            centre_rad,
            amplitude_rad,
            freq_hz,
        } => (centre_rad, amplitude_rad, freq_hz),
        Reference::Hold { s_rad } => (s_rad, 0.0, 1.0),
    };
    let mut out: Vec<VariedRun> = SINE_VARIATIONS
        .iter()
        .map(|&(a, f, k)| VariedRun {
            reference: Reference::Sine {
                centre_rad,
                amplitude_rad: amplitude_rad * a,
                freq_hz: freq_hz * f,
            },
            kp_per_s2: kp_per_s2 * k,
            pulse: None,
            duration_s: periods / (freq_hz * f),
        })
        .collect();
    for (sign, k) in [(1.0, 1.0), (-1.0, 0.7)] {
        out.push(VariedRun {
            reference: Reference::Hold { s_rad: hold_rad },
            kp_per_s2: kp_per_s2 * k,
            pulse: Some(Pulse {
                torque_nm: sign * pulse.torque_nm,
                ..pulse
            }),
            duration_s: 5.0_f64.max(pulse.end_s() + 1.0),
        });
    }
    // Interleave sines and pulses so a short list has both kinds.
    let order = [0, 4, 1, 2, 5, 3];
    order
        .iter()
        .take(runs.min(order.len()))
        .map(|&i| out[i])
        .collect()
}

/// The varied runs of joint `index` around `kp_per_s2` ([`varied_runs`] of its test sine, held at
/// its hold position, with a 1 s pulse of 15 Nm on the knee and 5 Nm on the ankle roll at 1 s). None
/// of them is the experiments' test sine: the amplitudes are 0.6–1.3× and the frequencies 0.7–1.5×
/// its own.
pub fn plans(index: usize, kp_per_s2: f64, runs: usize, periods: f64) -> Vec<RecordPlan> {
    let pulse = Pulse {
        start_s: 1.0,
        duration_s: 1.0,
        torque_nm: if index == 0 { 15.0 } else { 5.0 },
    };
    varied_runs(
        sine(index),
        hold_rad(index),
        pulse,
        kp_per_s2,
        runs,
        periods,
    )
    .into_iter()
    .map(|r| RecordPlan {
        index,
        reference: r.reference,
        kp_per_s2: r.kp_per_s2,
        pulse: r.pulse,
        duration_s: r.duration_s,
    })
    .collect()
}

/// Runs every plan with joint `index`'s model from `models` (one model per planned joint); returns
/// the traces in plan order. Runs of different joints share a trial.
pub fn record(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    cfg: &SuiteConfig,
    models: &[(usize, FrictionModel)],
    plans: &[RecordPlan],
) -> Result<Vec<JointTrace>, ExperimentError> {
    let mut grouped = vec![];
    for p in plans {
        let model = models
            .iter()
            .find(|(j, _)| *j == p.index)
            .map(|(_, m)| m.clone())
            .ok_or(ExperimentError::JointIndex(p.index))?;
        grouped.push((
            JointPlan {
                index: p.index,
                kp_per_s2: p.kp_per_s2,
                reference: p.reference,
                pulse: p.pulse,
                model,
            },
            p.duration_s,
        ));
    }
    suite::run_grouped(bins, setups, cfg, grouped, "on-policy")
}

/// Writes one joint's `traces` as an acquisition log `csv` (+ sidecar `csv` with `.json`): one
/// chunk per trace — split where a disturbance pulse acts, whose rows (±[`PULSE_MARGIN_ROWS`]) are
/// left out: the label r·k_t·i − τ_ID would count the external torque as friction — times offset so runs are [`RUN_GAP_S`] apart, `active` = 1, `mode` = 3,
/// `i_ref_a` = the current frictiond commanded after the row's sample (the trace's next row), the
/// true friction and φ̈ from the plant; the other simulator-only columns of a `frictl acquire` log
/// (LuGre state, flexspline torque, …) are not published by the plant and are absent.
/// `sidecar_extra` is merged into the sidecar (e.g. the runs' plans and the model).
pub fn write_raw_log(
    csv: &Path,
    setup: &JointSetup,
    traces: &[&JointTrace],
    seed: u64,
    sidecar_extra: serde_json::Value,
) -> Result<usize, ExperimentError> {
    let create = |p: &Path| {
        frictionless::output_file::AtomicFile::create(p).map_err(|source| ExperimentError::Create {
            path: p.to_owned(),
            source,
        })
    };
    let mut w = create(csv)?;
    // The truth the plant publishes (SimTruth); the rest of SIM_COLUMNS it does not.
    let truth_cols: Vec<_> = SIM_COLUMNS
        .iter()
        .filter(|c| matches!(c.name, "tau_f_true_nm" | "phi_ddot"))
        .copied()
        .collect();
    let names: Vec<&str> = COLUMNS.iter().chain(&truth_cols).map(|c| c.name).collect();
    writeln!(w, "{}", names.join(","))?;
    let mut t0 = 0.0;
    let mut rows = 0usize;
    let mut chunk = 0u32;
    for tr in traces {
        let n = tr.t_s.len();
        let keep = unlabelled_mask(&tr.tau_ext_nm, n);
        let mut in_segment = false;
        for (k, &kept) in keep.iter().enumerate() {
            if !kept {
                if in_segment {
                    chunk += 1;
                    in_segment = false;
                }
                continue;
            }
            in_segment = true;
            let i_ref = tr
                .i_ref_a
                .get(k + 1)
                .copied()
                .filter(|v| v.is_finite())
                .unwrap_or(f64::NAN);
            writeln!(
                w,
                "{:.3},{chunk},1,{MODE_CLOSED_LOOP},{:.9e},{:.12e},{:.9e},{:.6e},{:.6e},{:.3},{:.9e},{:.9e}",
                t0 + tr.t_s[k],
                tr.s_rad[k],
                tr.theta_motor_rad[k],
                tr.omega_motor_rad_s[k],
                i_ref,
                tr.i_meas_a.get(k).copied().unwrap_or(f64::NAN),
                tr.temperature_c.get(k).copied().unwrap_or(f64::NAN),
                tr.tau_f_true_nm[k],
                tr.phi_ddot_rad_s2.get(k).copied().unwrap_or(f64::NAN),
            )?;
            rows += 1;
        }
        if in_segment {
            chunk += 1;
        }
        t0 += tr.t_s.last().copied().unwrap_or(0.0) + RUN_GAP_S;
    }
    let mut columns: Vec<_> = COLUMNS.to_vec();
    columns.extend(truth_cols);
    let mut side = serde_json::json!({
        "format": "frictionless-acquire-v1",
        "producer": format!("frictl {}", env!("CARGO_PKG_VERSION")),
        "joint": setup.params.joint,
        "gear_ratio_signed": setup.params.gear_ratio_signed,
        "kt_nm_per_a": setup.params.kt_nm_per_a,
        "sample_period_s": 1e-3,
        "simulated": true,
        "source": SOURCE_CLOSED_LOOP,
        "seed": seed,
        "preset": setup.preset,
        "plant": setup.params,
        "csv": csv.file_name().map(|f| f.to_string_lossy().into_owned()),
        "columns": columns,
        "samples": rows,
        "chunks": chunk,
    });
    if let (Some(obj), serde_json::Value::Object(extra)) = (side.as_object_mut(), sidecar_extra) {
        obj.extend(extra);
    }
    let json_path = csv.with_extension("json");
    let text = serde_json::to_string_pretty(&side).map_err(std::io::Error::other)?;
    let mut side_out = create(&json_path)?;
    side_out.write_all(text.as_bytes())?;
    // The CSV and its sidecar replace the old pair together, the sidecar last.
    frictionless::output_file::commit_with_marker(vec![w], side_out)?;
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pulse_rows_and_their_margin_are_left_out() {
        let mut ext = vec![0.0; 400];
        ext[200..250].iter_mut().for_each(|v| *v = 5.0);
        let keep = unlabelled_mask(&ext, 400);
        assert!(keep[149] && !keep[150] && !keep[299] && keep[300]);
        assert_eq!(keep.iter().filter(|k| !**k).count(), 150);
    }

    #[test]
    fn plans_vary_around_the_gain_and_avoid_the_test_sine() {
        for index in [0, 1] {
            let test = sine(index);
            let ps = plans(index, 100.0, 6, 2.0);
            assert_eq!(ps.len(), 6);
            assert!(ps.iter().all(|p| p.reference != test));
            assert!(ps.iter().any(|p| p.kp_per_s2 < 100.0));
            assert!(ps.iter().any(|p| p.kp_per_s2 > 100.0));
            let pulses: Vec<f64> = ps
                .iter()
                .filter_map(|p| p.pulse.map(|x| x.torque_nm))
                .collect();
            assert!(pulses.iter().any(|&t| t > 0.0) && pulses.iter().any(|&t| t < 0.0));
            // A short list has a sine and a pulse.
            let two = plans(index, 100.0, 2, 2.0);
            assert!(two[0].pulse.is_none() && two[1].pulse.is_some());
        }
    }
}

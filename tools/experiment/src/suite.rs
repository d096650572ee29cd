//! The paper's three closed-loop experiments as functions over real trials.
//!
//! What this module **is**: [`track`] (sine tracking at given gains), [`min_kp`] (the lowest K_p per
//! joint and model that tracks within a [`TrackCriterion`], by [`KpBisection`]) and [`disturbance`]
//! (hold, external torque pulse, release, position RMSE after release). Tasks on *different* joints
//! share a trial (the knee and the ankle roll are independent plants in one plant process), so a
//! `both` run costs no more trials than one joint. In lockstep, trials of one batch run
//! [`SuiteConfig::jobs`] at a time, each with its own frictiond, plant and IPC namespace: a lockstep
//! trial is a chain of processes waking one another and leaves a core mostly idle, and its result
//! does not depend on what else runs, so only the wall time changes.
//!
//! The references (paper-like, reference doc §9): ankle roll `0 − 0.15·cos(2π·0.25·t)` rad, knee
//! `−0.8 − 0.4·cos(2π·0.2·t)` rad (centred in the knee's range, gravity-loaded); disturbance holds
//! at the sine centre.
//!
//! What it is **not**: no tables or files (see [`super::report`]).

use super::ExperimentError;
use super::controller::Reference;
use super::metrics::{self, DisturbanceMetrics, TrackCriterion, TrackMetrics};
use super::rig::JointSetup;
use super::run::{JointPlan, JointTrace, Pulse, TrialOptions, TrialSpec, run_trial_with};
use super::search::{KpBisection, MinKp};
use super::session::{Binaries, FrictionModel, Lpf, Mode};

/// Settings shared by every trial of a suite.
#[derive(Clone, Debug)]
pub struct SuiteConfig {
    /// Lockstep or real time.
    pub mode: Mode,
    /// Plant seed.
    pub seed: u64,
    /// Plant `--set` overrides.
    pub sets: Vec<String>,
    /// Pass criterion of the tracking trials.
    pub criterion: TrackCriterion,
    /// Sine periods per tracking trial (the first `criterion.skip_periods` are not evaluated).
    pub periods: f64,
    /// K_p search range [1/s²] per joint index.
    pub kp_range: [(f64, f64); 2],
    /// Bisection halvings.
    pub iterations: u32,
    /// Disturbance pulse per joint index.
    pub pulse: [Pulse; 2],
    /// Observation time after the release [s].
    pub after_release_s: f64,
    /// Print one progress line per trial.
    pub progress: bool,
    /// PINN Δθ offset for frictiond (see [`TrialSpec::pinn_delta_theta_offset_motor_rad`]).
    pub pinn_delta_theta_offset_motor_rad: [Option<f64>; 2],
    /// `kfc` per joint index instead of the shipped config's (`None` = shipped).
    pub kfc: [Option<f64>; 2],
    /// τ̂_F low-pass per joint index instead of the shipped config's (`None` = shipped).
    pub lpf: [Option<Lpf>; 2],
    /// Reflected rotor inertia in the controller's M (see [`TrialOptions::rotor_inertia_in_m`]).
    pub rotor_inertia_in_m: bool,
    /// Trials run at once (≥ 1; real-time trials run one at a time whatever this says).
    pub jobs: usize,
}

/// The sine reference of joint `index` (0 = knee, 1 = ankle_roll).
pub fn sine(index: usize) -> Reference {
    if index == 0 {
        Reference::Sine {
            centre_rad: -0.8,
            amplitude_rad: 0.4,
            freq_hz: 0.2,
        }
    } else {
        Reference::Sine {
            centre_rad: 0.0,
            amplitude_rad: 0.15,
            freq_hz: 0.25,
        }
    }
}

/// Amplitude and frequency of a sine reference (0, 0 for a hold).
pub(crate) fn amp_freq(r: &Reference) -> (f64, f64) {
    match *r {
        Reference::Sine {
            amplitude_rad,
            freq_hz,
            ..
        } => (amplitude_rad, freq_hz),
        Reference::Hold { .. } => (0.0, 0.0),
    }
}

/// The held position of the disturbance test for joint `index` (the sine centre).
pub fn hold_rad(index: usize) -> f64 {
    match sine(index) {
        Reference::Sine { centre_rad, .. } => centre_rad,
        Reference::Hold { s_rad } => s_rad,
    }
}

/// One (joint, model, gain) to run.
#[derive(Clone, Debug)]
pub struct Task {
    /// Joint index (0 = knee, 1 = ankle_roll).
    pub index: usize,
    /// Friction model in frictiond.
    pub model: FrictionModel,
    /// K_p [1/s²].
    pub kp_per_s2: f64,
}

/// Runs `plans` (each with its duration [s]) grouped so each trial has distinct joints, up to
/// [`SuiteConfig::jobs`] trials at once in lockstep; returns traces in plan order. The first error
/// (in trial order) is returned once the trials under way have ended; no new trial starts after one.
pub fn run_grouped(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    cfg: &SuiteConfig,
    plans: Vec<(JointPlan, f64)>,
    label: &str,
) -> Result<Vec<JointTrace>, ExperimentError> {
    let mut groups: Vec<Vec<usize>> = vec![];
    let mut pending: Vec<usize> = (0..plans.len()).collect();
    while !pending.is_empty() {
        let mut group: Vec<usize> = vec![];
        for &p in &pending {
            if !group.iter().any(|&g| plans[g].0.index == plans[p].0.index) {
                group.push(p);
            }
        }
        pending.retain(|p| !group.contains(p));
        groups.push(group);
    }
    let run_group = |group: &Vec<usize>| {
        let spec = TrialSpec {
            mode: cfg.mode,
            duration_s: group.iter().map(|&g| plans[g].1).fold(0.0, f64::max),
            joints: group.iter().map(|&g| plans[g].0.clone()).collect(),
            seed: cfg.seed,
            sets: cfg.sets.clone(),
            pinn_delta_theta_offset_motor_rad: cfg.pinn_delta_theta_offset_motor_rad.to_vec(),
            raw_friction: false,
            kfc: cfg.kfc.to_vec(),
        };
        let trace = run_trial_with(
            bins,
            setups,
            &spec,
            &TrialOptions {
                lpf: cfg.lpf.to_vec(),
                rotor_inertia_in_m: cfg.rotor_inertia_in_m,
            },
        )?;
        if cfg.progress {
            let who: Vec<String> = trace
                .joints
                .iter()
                .map(|j| format!("{}/{} K_p {:.4}", j.name, j.model, j.kp_per_s2))
                .collect();
            eprintln!(
                "  {label}: {} — {} ticks in {:.2} s ({:.1}× real time)",
                who.join(", "),
                trace.ticks,
                trace.total_wall_s,
                trace.ticks as f64 * 1e-3 / trace.total_wall_s.max(1e-9)
            );
        }
        Ok(trace)
    };
    let jobs = match cfg.mode {
        Mode::Lockstep => cfg.jobs.max(1),
        Mode::Realtime => 1,
    };
    // Fewer trials than jobs: give joints sharing a trial trials of their own (each plant has its
    // own seed and each joint its own law, so a joint's trace does not depend on its company).
    while groups.len() < jobs {
        let Some(k) = groups.iter().position(|g| g.len() > 1) else {
            break;
        };
        let last = groups[k].pop().expect("len > 1");
        groups.insert(k + 1, vec![last]);
    }
    let jobs = jobs.min(groups.len().max(1));
    let results = run_parallel(jobs, &groups, run_group);
    let mut out: Vec<Option<JointTrace>> = vec![None; plans.len()];
    for (group, result) in groups.iter().zip(results) {
        // `None`: not started because an earlier trial failed; that error comes first.
        let Some(trace) = result else { continue };
        for (&g, jt) in group.iter().zip(trace?.joints) {
            out[g] = Some(jt);
        }
    }
    Ok(out
        .into_iter()
        .map(|t| t.expect("every plan ran"))
        .collect())
}

/// Runs `f` on every item with up to `jobs` threads, results in item order; after the first error
/// no further item starts (those are `None`).
pub(crate) fn run_parallel<T: Sync, R: Send>(
    jobs: usize,
    items: &[T],
    f: impl Fn(&T) -> Result<R, ExperimentError> + Sync,
) -> Vec<Option<Result<R, ExperimentError>>> {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let results: Mutex<Vec<Option<Result<R, ExperimentError>>>> =
        Mutex::new(items.iter().map(|_| None).collect());
    let work = || {
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            if k >= items.len() || failed.load(Ordering::Relaxed) {
                return;
            }
            let r = f(&items[k]);
            if r.is_err() {
                failed.store(true, Ordering::Relaxed);
            }
            results.lock().unwrap_or_else(|e| e.into_inner())[k] = Some(r);
        }
    };
    if jobs <= 1 {
        work();
    } else {
        std::thread::scope(|s| {
            for _ in 0..jobs {
                s.spawn(work);
            }
        });
    }
    results.into_inner().unwrap_or_else(|e| e.into_inner())
}

/// A tracking run's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TrackResult {
    /// Task.
    pub index: usize,
    /// Model label.
    pub model: String,
    /// K_p [1/s²].
    pub kp_per_s2: f64,
    /// Metrics over the evaluation window.
    pub metrics: TrackMetrics,
    /// Whether RMSE ≤ the criterion's threshold.
    pub passed: bool,
    /// The recorded signals.
    #[serde(skip)]
    pub trace: JointTrace,
}

/// Sine tracking for every task (see the module doc).
pub fn track(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    cfg: &SuiteConfig,
    tasks: &[Task],
    label: &str,
) -> Result<Vec<TrackResult>, ExperimentError> {
    let plans = tasks
        .iter()
        .map(|t| {
            let r = sine(t.index);
            let (_, f) = amp_freq(&r);
            (
                JointPlan {
                    index: t.index,
                    kp_per_s2: t.kp_per_s2,
                    reference: r,
                    pulse: None,
                    model: t.model.clone(),
                },
                cfg.periods / f,
            )
        })
        .collect();
    let traces = run_grouped(bins, setups, cfg, plans, label)?;
    Ok(tasks
        .iter()
        .zip(traces)
        .map(|(t, trace)| {
            let (a, f) = amp_freq(&sine(t.index));
            let m = metrics::track(&trace, cfg.criterion.skip_periods / f, cfg.periods / f);
            TrackResult {
                index: t.index,
                model: t.model.label().to_owned(),
                kp_per_s2: t.kp_per_s2,
                passed: m.rmse_rad <= cfg.criterion.threshold_rad(a),
                metrics: m,
                trace,
            }
        })
        .collect())
}

/// One evaluated gain of a search.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct SearchStep {
    /// K_p [1/s²].
    pub kp_per_s2: f64,
    /// Tracking RMSE [rad].
    #[serde(deserialize_with = "super::metrics::null_as_nan")]
    pub rmse_rad: f64,
    /// Passed the criterion.
    pub passed: bool,
}

/// A minimum-K_p search's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MinKpResult {
    /// Joint index.
    pub index: usize,
    /// Model label.
    pub model: String,
    /// The answer.
    pub min_kp: MinKp,
    /// Every trial of the search.
    pub steps: Vec<SearchStep>,
    /// The tracking run at the lowest passing gain (None if nothing passed).
    pub at_min: Option<TrackResult>,
}

/// Minimum-K_p search for every (joint, model) task (`kp_per_s2` of the tasks is ignored).
pub fn min_kp(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    cfg: &SuiteConfig,
    tasks: &[Task],
) -> Result<Vec<MinKpResult>, ExperimentError> {
    let mut searches: Vec<KpBisection> = tasks
        .iter()
        .map(|t| {
            let (lo, hi) = cfg.kp_range[t.index];
            KpBisection::new(lo, hi, cfg.iterations)
        })
        .collect::<Result<_, _>>()?;
    let mut steps: Vec<Vec<SearchStep>> = vec![vec![]; tasks.len()];
    let mut best: Vec<Option<TrackResult>> = vec![None; tasks.len()];
    let mut round = 0;
    loop {
        let live: Vec<usize> = (0..tasks.len())
            .filter(|&i| searches[i].candidate().is_some())
            .collect();
        if live.is_empty() {
            break;
        }
        round += 1;
        let batch: Vec<Task> = live
            .iter()
            .map(|&i| Task {
                kp_per_s2: searches[i].candidate().expect("live"),
                ..tasks[i].clone()
            })
            .collect();
        let results = track(bins, setups, cfg, &batch, &format!("min-kp round {round}"))?;
        for (&i, r) in live.iter().zip(results) {
            searches[i].report(r.passed);
            steps[i].push(SearchStep {
                kp_per_s2: r.kp_per_s2,
                rmse_rad: r.metrics.rmse_rad,
                passed: r.passed,
            });
            if r.passed && best[i].as_ref().is_none_or(|b| r.kp_per_s2 < b.kp_per_s2) {
                best[i] = Some(r);
            }
        }
    }
    Ok(tasks
        .iter()
        .enumerate()
        .map(|(i, t)| MinKpResult {
            index: t.index,
            model: t.model.label().to_owned(),
            min_kp: searches[i].result().expect("done"),
            steps: std::mem::take(&mut steps[i]),
            at_min: best[i].take(),
        })
        .collect())
}

/// A disturbance run's result.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DisturbanceResult {
    /// Joint index.
    pub index: usize,
    /// Model label.
    pub model: String,
    /// K_p [1/s²].
    pub kp_per_s2: f64,
    /// The pulse.
    pub pulse: Pulse,
    /// Metrics.
    pub metrics: DisturbanceMetrics,
    /// The recorded signals.
    #[serde(skip)]
    pub trace: JointTrace,
}

/// Disturbance rejection for every task: hold at [`hold_rad`], the joint's pulse, then
/// `after_release_s` of observation.
pub fn disturbance(
    bins: &Binaries,
    setups: &[JointSetup; 2],
    cfg: &SuiteConfig,
    tasks: &[Task],
    label: &str,
) -> Result<Vec<DisturbanceResult>, ExperimentError> {
    let plans = tasks
        .iter()
        .map(|t| {
            let pulse = cfg.pulse[t.index];
            (
                JointPlan {
                    index: t.index,
                    kp_per_s2: t.kp_per_s2,
                    reference: Reference::Hold {
                        s_rad: hold_rad(t.index),
                    },
                    pulse: Some(pulse),
                    model: t.model.clone(),
                },
                pulse.end_s() + cfg.after_release_s,
            )
        })
        .collect();
    let traces = run_grouped(bins, setups, cfg, plans, label)?;
    Ok(tasks
        .iter()
        .zip(traces)
        .map(|(t, trace)| {
            let pulse = cfg.pulse[t.index];
            DisturbanceResult {
                index: t.index,
                model: t.model.label().to_owned(),
                kp_per_s2: t.kp_per_s2,
                pulse,
                metrics: metrics::disturbance(&trace, hold_rad(t.index), &pulse),
                trace,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_parallel_keeps_item_order_and_stops_starting_after_an_error() {
        let items: Vec<u64> = (0..9).collect();
        for jobs in [1, 2, 4, 20] {
            let out = run_parallel(jobs, &items, |&k| {
                // Later items finish first when run at once.
                std::thread::sleep(std::time::Duration::from_millis(9 - k));
                Ok(k * 10)
            });
            let got: Vec<u64> = out.into_iter().map(|r| r.unwrap().unwrap()).collect();
            assert_eq!(
                got,
                (0..9).map(|k| k * 10).collect::<Vec<_>>(),
                "jobs {jobs}"
            );
        }
        let started = std::sync::atomic::AtomicUsize::new(0);
        let out = run_parallel(1, &items, |&k| {
            started.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if k == 3 {
                Err(ExperimentError::Interrupted)
            } else {
                Ok(k)
            }
        });
        assert_eq!(
            started.into_inner(),
            4,
            "nothing starts after the failing item"
        );
        assert!(matches!(out[3], Some(Err(ExperimentError::Interrupted))));
        assert!(out[4..].iter().all(Option::is_none));
    }
}

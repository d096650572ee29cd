//! The paper's closed-loop experiments on the coupled six-joint leg (`frictl sim serve --preset leg`).
//!
//! What this module **is**: [`LegSuiteConfig`] and [`run_leg_suite`]: for each tested joint (normally the knee and the ankle
//! roll) and each compensation ([`LegModel`]: one friction model per leg joint, run by one frictiond
//! with six joints), the minimum-K_p search ([`KpBisection`] over sine-tracking trials) and a
//! disturbance trial (hold, external torque pulse, release), while every other joint of the leg holds
//! its preset pose or moves on a small sine ([`RestMotion`]) under the same controller. Every trial
//! is a real lockstep run of the plant, frictiond and this controller (see [`super::run`]); one trial
//! tests one joint (the leg is coupled, so two tested joints in one trial would disturb each other).
//! The result is a serde-serialisable [`LegSuiteReport`] keyed by joint, then model label.
//!
//! What it is **not**: no physics, no friction model evaluation, no files (the CLI writes them).

use std::collections::BTreeMap;

use super::ExperimentError;
use super::controller::Reference;
use super::metrics::{self, DisturbanceMetrics, TrackCriterion, TrackMetrics};
use super::rig::{LegSetup, Rig};
use super::run::{JointPlan, JointTrace, Pulse, TrialOptions, TrialSpec, run_trial_on};
use super::search::{KpBisection, MinKp};
use super::session::{Binaries, FrictionModel, Lpf, Mode};
use super::suite::{SearchStep, amp_freq, run_parallel};

/// What the joints not under test do during a trial.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RestMotion {
    /// Hold the preset's initial pose.
    Hold,
    /// Small sines around the preset's initial pose (`pose − A·cos(2π f t)`, starting at rest at
    /// `pose − A`), the same amplitude and frequency for every resting joint.
    Sines {
        /// Amplitude A [rad].
        amplitude_rad: f64,
        /// Frequency f [Hz].
        freq_hz: f64,
    },
}

/// One tested joint of the leg.
#[derive(Clone, Debug, PartialEq)]
pub struct LegTestJoint {
    /// Joint name (`l_knee`, `l_ankle_roll`).
    pub name: String,
    /// Sine reference of the tracking trials (the disturbance trial holds its centre).
    pub sine: Reference,
    /// K_p search range [1/s²].
    pub kp_range: (f64, f64),
    /// External torque pulse of the disturbance trial.
    pub pulse: Pulse,
    /// K_p of the disturbance trial [1/s²] (the same for every model).
    pub disturbance_kp_per_s2: f64,
}

impl LegTestJoint {
    /// The knee: the single-joint suite's reference (`−0.8 − 0.4·cos(2π·0.2·t)` rad), K_p in
    /// [5, 5000], a 15 Nm pulse of 1 s at 1 s (the single-joint suite's), disturbance at K_p = 1000.
    pub fn knee() -> Self {
        Self {
            name: "l_knee".into(),
            sine: super::suite::sine(0),
            kp_range: (5.0, 5000.0),
            pulse: Pulse {
                start_s: 1.0,
                duration_s: 1.0,
                torque_nm: 15.0,
            },
            disturbance_kp_per_s2: 1000.0,
        }
    }

    /// The ankle roll: `0 − 0.15·cos(2π·0.25·t)` rad, K_p in [50, 100000], a 5 Nm pulse of 1 s at
    /// 1 s (the single-joint suite's), disturbance at K_p = 30000.
    pub fn ankle_roll() -> Self {
        Self {
            name: "l_ankle_roll".into(),
            sine: super::suite::sine(1),
            kp_range: (50.0, 100_000.0),
            pulse: Pulse {
                start_s: 1.0,
                duration_s: 1.0,
                torque_nm: 5.0,
            },
            disturbance_kp_per_s2: 30_000.0,
        }
    }
}

impl LegTestJoint {
    /// The knee (`−0.8 − 0.3·cos(2π·0.5·t)` rad, K_p in [10, 3000]) and the ankle roll
    /// (`−0.1·cos(2π·0.5·t)` rad, K_p in [300, 100000]) on faster, smaller sines than the paper's:
    /// the small sizes of the tests and of `frictl demo --robot leg --quick`.
    pub fn fast_pair() -> Vec<Self> {
        vec![
            Self {
                sine: Reference::Sine {
                    centre_rad: -0.8,
                    amplitude_rad: 0.3,
                    freq_hz: 0.5,
                },
                kp_range: (10.0, 3000.0),
                ..Self::knee()
            },
            Self {
                sine: Reference::Sine {
                    centre_rad: 0.0,
                    amplitude_rad: 0.1,
                    freq_hz: 0.5,
                },
                kp_range: (300.0, 100_000.0),
                ..Self::ankle_roll()
            },
        ]
    }
}

/// One compensation of the whole leg: frictiond's model per leg joint.
#[derive(Clone, Debug, PartialEq)]
pub struct LegModel {
    /// Report key (`none`, `CV`, `SCV`, `PINN`, `oracle (true friction)`).
    pub label: String,
    /// Model per payload joint (one per leg joint).
    pub per_joint: Vec<FrictionModel>,
    /// A PINN joint's fixed Δθ offset [motor rad] per payload joint (`None` or no entry: latched
    /// at enable), as frictiond's `delta_theta_offset_motor_rad`.
    pub delta_theta_offset_motor_rad: Vec<Option<f64>>,
    /// `kfc` per payload joint (`None` or no entry: the shipped law's).
    pub kfc: Vec<Option<f64>>,
    /// τ̂_F low-pass per payload joint (`None` or no entry: the shipped law's).
    pub lpf: Vec<Option<Lpf>>,
}

impl LegModel {
    /// `model` on every one of `n` joints, labelled as the model, with the shipped law.
    pub fn uniform(model: FrictionModel, n: usize) -> Self {
        Self::per_joint(model.label(), vec![model; n])
    }

    /// `per_joint` models (payload order) under `label`, with the shipped law and Δθ offsets
    /// latched at enable.
    pub fn per_joint(label: &str, per_joint: Vec<FrictionModel>) -> Self {
        Self {
            label: label.to_owned(),
            per_joint,
            delta_theta_offset_motor_rad: Vec::new(),
            kfc: Vec::new(),
            lpf: Vec::new(),
        }
    }
}

impl LegModel {
    /// The compensation a frictiond config describes (e.g. the one `frictl robot run` writes), by
    /// joint name: each leg joint runs the config's model for the joint of the same name (CV, SCV,
    /// PINN or none) with the config's `kfc`, `lpf` and `delta_theta_offset_motor_rad`, and `none`
    /// if the config does not list it. A LuGre joint is an error (the experiments compare none /
    /// CV / SCV / PINN).
    pub fn from_daemon_config(
        label: &str,
        path: &std::path::Path,
        leg: &LegSetup,
    ) -> Result<Self, ExperimentError> {
        use frictiond_config::ModelSpec;
        let cfg = frictiond_config::load(path).map_err(|source| ExperimentError::DaemonConfig {
            path: path.to_owned(),
            source: Box::new(source),
        })?;
        let mut per_joint = vec![FrictionModel::None; leg.dof()];
        let mut offsets = vec![None; leg.dof()];
        let mut kfc = vec![None; leg.dof()];
        let mut lpf = vec![None; leg.dof()];
        if !cfg.raw.joint.iter().any(|raw| leg.index(&raw.name).is_ok()) {
            let names = |v: Vec<&str>| v.join(", ");
            return Err(ExperimentError::LegConfigNoJoint {
                path: path.to_owned(),
                joints: names(cfg.raw.joint.iter().map(|j| j.name.as_str()).collect()),
                leg: names(leg.params.joints.iter().map(|p| p.joint.as_str()).collect()),
            });
        }
        for (raw, spec) in cfg.raw.joint.iter().zip(&cfg.models) {
            let Ok(i) = leg.index(&raw.name) else {
                continue;
            };
            offsets[i] = raw.delta_theta_offset_motor_rad;
            kfc[i] = Some(raw.kfc);
            // No `lpf` key in the config is no filter, not the shipped one.
            lpf[i] = Some(Lpf::from(raw.lpf));
            per_joint[i] = match spec {
                ModelSpec::None => FrictionModel::None,
                ModelSpec::Cv(p) => FrictionModel::Cv(*p),
                ModelSpec::Scv(p) => FrictionModel::Scv(*p),
                ModelSpec::Pinn { path, .. } => FrictionModel::Pinn(path.clone()),
                ModelSpec::Lugre(_) => {
                    return Err(ExperimentError::LegModelKind {
                        path: path.to_owned(),
                        joint: raw.name.clone(),
                    });
                }
            };
        }
        Ok(Self {
            label: label.to_owned(),
            per_joint,
            delta_theta_offset_motor_rad: offsets,
            kfc,
            lpf,
        })
    }
}

/// Everything [`run_leg_suite`] needs.
#[derive(Clone, Debug)]
pub struct LegSuiteConfig {
    /// `frictl` (the plant server) and `frictiond`.
    pub bins: Binaries,
    /// Plant seed.
    pub seed: u64,
    /// Plant `--set` overrides (also applied to the controller's model of the drives).
    pub sets: Vec<String>,
    /// The tested joints.
    pub joints: Vec<LegTestJoint>,
    /// The compensations compared.
    pub models: Vec<LegModel>,
    /// What the other joints do.
    pub rest: RestMotion,
    /// K_p of the joints not under test [1/s²].
    pub rest_kp_per_s2: f64,
    /// Pass criterion of the tracking trials.
    pub criterion: TrackCriterion,
    /// Sine periods per tracking trial (the first `criterion.skip_periods` are not evaluated).
    pub periods: f64,
    /// Bisection halvings.
    pub iterations: u32,
    /// Observation time after the pulse's release [s].
    pub after_release_s: f64,
    /// Add each drive's reflected rotor inertia r²·J_m to the controller's M diagonal (the paper's
    /// M is the link inertia only).
    pub rotor_inertia_in_m: bool,
    /// Trials run at once (≥ 1).
    pub jobs: usize,
    /// Print one line per trial.
    pub progress: bool,
}

impl LegSuiteConfig {
    /// The knee and the ankle roll, the rest holding at K_p = 5000, the paper's criterion (RMSE ≤
    /// 10 % of the amplitude after one period), 2 periods, 4 halvings, 1.5 s after the release.
    pub fn paper(bins: Binaries, models: Vec<LegModel>) -> Self {
        Self {
            bins,
            seed: 1,
            sets: vec![],
            joints: vec![LegTestJoint::knee(), LegTestJoint::ankle_roll()],
            models,
            rest: RestMotion::Hold,
            rest_kp_per_s2: 5000.0,
            criterion: TrackCriterion {
                frac_of_amplitude: 0.1,
                skip_periods: 1.0,
            },
            periods: 2.0,
            iterations: 4,
            after_release_s: 1.5,
            rotor_inertia_in_m: false,
            jobs: 1,
            progress: false,
        }
    }
}

/// Results of one (joint, model).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct LegCell {
    /// Minimum K_p (`min_kp.kp` when found).
    pub min_kp: MinKp,
    /// Every gain the search tried.
    pub search: Vec<SearchStep>,
    /// Tracking at the minimum K_p (none if nothing passed).
    pub track_at_min_kp: Option<TrackMetrics>,
    /// K_p of the disturbance trial [1/s²].
    pub disturbance_kp_per_s2: f64,
    /// Disturbance-rejection metrics.
    pub disturbance: DisturbanceMetrics,
    /// Largest |s − s_d| of the other joints during the disturbance trial [rad] (how much the
    /// coupling moved them).
    pub rest_max_abs_err_rad: f64,
}

/// One tested joint's results.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct LegJointReport {
    /// Reference of the tracking trials.
    pub reference: String,
    /// The disturbance pulse.
    pub pulse: Option<Pulse>,
    /// Model label → results.
    pub models: BTreeMap<String, LegCell>,
}

/// Results of [`run_leg_suite`], keyed by joint then model: `joints.l_knee.models.SCV.min_kp.kp`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct LegSuiteReport {
    /// What the joints not under test did.
    pub rest: RestMotion,
    /// Their K_p [1/s²].
    pub rest_kp_per_s2: f64,
    /// K_d [1/s].
    pub kd_per_s: f64,
    /// Tracking criterion of the K_p search.
    pub criterion: TrackCriterion,
    /// Plant seed.
    pub seed: u64,
    /// Tested joint → results.
    pub joints: BTreeMap<String, LegJointReport>,
    /// Trials run.
    pub trials: usize,
    /// Wall-clock seconds.
    pub wall_s: f64,
}

/// The centre of a sine (the held position for a hold).
fn centre(r: &Reference) -> f64 {
    match *r {
        Reference::Sine { centre_rad, .. } => centre_rad,
        Reference::Hold { s_rad } => s_rad,
    }
}

/// One trial of the suite: tested joint `tested` (payload index) with `kp`, `reference` and `pulse`.
struct LegTrial {
    tested: usize,
    model: usize,
    kp_per_s2: f64,
    reference: Reference,
    pulse: Option<Pulse>,
    duration_s: f64,
}

/// Runs one trial; returns every joint's trace in payload order.
fn run_one(
    cfg: &LegSuiteConfig,
    leg: &LegSetup,
    t: &LegTrial,
) -> Result<Vec<JointTrace>, ExperimentError> {
    let model = &cfg.models[t.model];
    let joints = (0..leg.dof())
        .map(|i| {
            if i == t.tested {
                JointPlan {
                    index: i,
                    kp_per_s2: t.kp_per_s2,
                    reference: t.reference,
                    pulse: t.pulse,
                    model: model.per_joint[i].clone(),
                }
            } else {
                let pose = leg.params.joints[i].initial_s_rad;
                JointPlan {
                    index: i,
                    kp_per_s2: cfg.rest_kp_per_s2,
                    reference: match cfg.rest {
                        RestMotion::Hold => Reference::Hold { s_rad: pose },
                        RestMotion::Sines {
                            amplitude_rad,
                            freq_hz,
                        } => Reference::Sine {
                            centre_rad: pose,
                            amplitude_rad,
                            freq_hz,
                        },
                    },
                    pulse: None,
                    model: model.per_joint[i].clone(),
                }
            }
        })
        .collect();
    let spec = TrialSpec {
        mode: Mode::Lockstep,
        duration_s: t.duration_s,
        joints,
        seed: cfg.seed,
        sets: cfg.sets.clone(),
        pinn_delta_theta_offset_motor_rad: model.delta_theta_offset_motor_rad.clone(),
        raw_friction: false,
        kfc: model.kfc.clone(),
    };
    let opts = TrialOptions {
        lpf: model.lpf.clone(),
        rotor_inertia_in_m: cfg.rotor_inertia_in_m,
    };
    let trace = run_trial_on(&cfg.bins, &Rig::Leg(leg), &spec, &opts)?;
    if cfg.progress {
        eprintln!(
            "  leg {} / {} K_p {:.4}: {} ticks in {:.2} s",
            leg.params.joints[t.tested].joint,
            model.label,
            t.kp_per_s2,
            trace.ticks,
            trace.total_wall_s
        );
    }
    Ok(trace.joints)
}

/// Runs the whole-leg experiments of `cfg` (see the module doc): per tested joint and model, the
/// minimum-K_p search and one disturbance trial. Errors: an unknown joint name, a model list whose
/// length is not the leg's joint count, an empty or invalid K_p range, any trial's failure.
pub fn run_leg_suite(cfg: &LegSuiteConfig) -> Result<LegSuiteReport, ExperimentError> {
    let started = std::time::Instant::now();
    super::session::install_signal_flag()?;
    let leg = LegSetup::load(&cfg.sets)?;
    let n = leg.dof();
    for m in &cfg.models {
        if m.per_joint.len() != n {
            return Err(ExperimentError::LegModels {
                label: m.label.clone(),
                got: m.per_joint.len(),
                expected: n,
            });
        }
    }
    let tested: Vec<usize> = cfg
        .joints
        .iter()
        .map(|j| leg.index(&j.name))
        .collect::<Result<_, _>>()?;
    // (tested joint, model) pairs, each with its search
    let pairs: Vec<(usize, usize)> = (0..cfg.joints.len())
        .flat_map(|j| (0..cfg.models.len()).map(move |m| (j, m)))
        .collect();
    let mut searched = min_kp_searches(cfg, &leg, &tested, &pairs)?;
    let mut trials = searched.trials;
    // disturbance: hold the sine's centre, the pulse, then observe
    let dist: Vec<LegTrial> = pairs
        .iter()
        .map(|&(j, m)| {
            let tj = &cfg.joints[j];
            LegTrial {
                tested: tested[j],
                model: m,
                kp_per_s2: tj.disturbance_kp_per_s2,
                reference: Reference::Hold {
                    s_rad: centre(&tj.sine),
                },
                pulse: Some(tj.pulse),
                duration_s: tj.pulse.end_s() + cfg.after_release_s,
            }
        })
        .collect();
    let results = run_parallel(cfg.jobs.max(1), &dist, |t| run_one(cfg, &leg, t));
    trials += dist.len();
    let mut report = LegSuiteReport {
        rest: cfg.rest,
        rest_kp_per_s2: cfg.rest_kp_per_s2,
        kd_per_s: super::controller::PAPER_KD_PER_S,
        criterion: cfg.criterion,
        seed: cfg.seed,
        joints: BTreeMap::new(),
        trials,
        wall_s: 0.0,
    };
    for (i, ((&(j, m), t), r)) in pairs.iter().zip(&dist).zip(results).enumerate() {
        let Some(r) = r else { continue };
        let traces = r?;
        let tj = &cfg.joints[j];
        let pulse = tj.pulse;
        let rest_max_abs_err_rad = traces
            .iter()
            .filter(|tr| tr.index != t.tested)
            .flat_map(|tr| {
                tr.s_des_rad
                    .iter()
                    .zip(&tr.s_rad)
                    .map(|(d, s)| (d - s).abs())
            })
            .fold(0.0, f64::max);
        let cell = LegCell {
            min_kp: searched.searches[i].result().expect("search done"),
            search: std::mem::take(&mut searched.steps[i]),
            track_at_min_kp: searched.best[i].map(|(_, m)| m),
            disturbance_kp_per_s2: tj.disturbance_kp_per_s2,
            disturbance: metrics::disturbance(&traces[t.tested], centre(&tj.sine), &pulse),
            rest_max_abs_err_rad,
        };
        let jr = report
            .joints
            .entry(tj.name.clone())
            .or_insert_with(|| LegJointReport {
                reference: format!("{:?}", tj.sine),
                pulse: Some(pulse),
                models: BTreeMap::new(),
            });
        jr.models.insert(cfg.models[m].label.clone(), cell);
    }
    report.wall_s = started.elapsed().as_secs_f64();
    Ok(report)
}

/// The min-K_p searches of every (tested joint, model) pair, run in batches of one trial per live
/// search.
struct Searches {
    /// Per pair, its bisection.
    searches: Vec<KpBisection>,
    /// Per pair, its trials in order.
    steps: Vec<Vec<SearchStep>>,
    /// Per pair, the lowest passing K_p and its tracking metrics.
    best: Vec<Option<(f64, TrackMetrics)>>,
    /// Trials run.
    trials: usize,
}

/// Runs the min-K_p search of every (tested joint index in `cfg.joints`, model) pair in `pairs`
/// (`tested`: each tested joint's payload index) to its end.
fn min_kp_searches(
    cfg: &LegSuiteConfig,
    leg: &LegSetup,
    tested: &[usize],
    pairs: &[(usize, usize)],
) -> Result<Searches, ExperimentError> {
    let mut searches: Vec<KpBisection> = pairs
        .iter()
        .map(|&(j, _)| {
            let (lo, hi) = cfg.joints[j].kp_range;
            KpBisection::new(lo, hi, cfg.iterations)
        })
        .collect::<Result<_, _>>()?;
    let mut steps: Vec<Vec<SearchStep>> = vec![vec![]; pairs.len()];
    let mut best: Vec<Option<(f64, TrackMetrics)>> = vec![None; pairs.len()];
    let mut trials = 0usize;
    loop {
        let live: Vec<usize> = (0..pairs.len())
            .filter(|&i| searches[i].candidate().is_some())
            .collect();
        if live.is_empty() {
            break;
        }
        let batch: Vec<LegTrial> = live
            .iter()
            .map(|&i| {
                let (j, m) = pairs[i];
                let (_, f) = amp_freq(&cfg.joints[j].sine);
                LegTrial {
                    tested: tested[j],
                    model: m,
                    kp_per_s2: searches[i].candidate().expect("live"),
                    reference: cfg.joints[j].sine,
                    pulse: None,
                    duration_s: cfg.periods / f,
                }
            })
            .collect();
        let results = run_parallel(cfg.jobs.max(1), &batch, |t| run_one(cfg, leg, t));
        trials += batch.len();
        for ((&i, t), r) in live.iter().zip(&batch).zip(results) {
            let Some(r) = r else { continue };
            let traces = r?;
            let (j, _) = pairs[i];
            let (a, f) = amp_freq(&cfg.joints[j].sine);
            let m = metrics::track(
                &traces[t.tested],
                cfg.criterion.skip_periods / f,
                cfg.periods / f,
            );
            let passed = m.rmse_rad <= cfg.criterion.threshold_rad(a);
            searches[i].report(passed);
            steps[i].push(SearchStep {
                kp_per_s2: t.kp_per_s2,
                rmse_rad: m.rmse_rad,
                passed,
            });
            if passed && best[i].is_none_or(|(kp, _)| t.kp_per_s2 < kp) {
                best[i] = Some((t.kp_per_s2, m));
            }
        }
    }
    Ok(Searches {
        searches,
        steps,
        best,
        trials,
    })
}

/// One on-policy run of the leg ([`record_leg`]): tested joint `joint` (an index into
/// [`LegSuiteConfig::joints`]) follows `reference` at `kp_per_s2` (with `pulse`, if any) while the
/// rest holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct LegRecordPlan {
    /// Index into [`LegSuiteConfig::joints`].
    pub joint: usize,
    /// Reference of the tested joint.
    pub reference: Reference,
    /// K_p of the tested joint [1/s²].
    pub kp_per_s2: f64,
    /// External torque pulse on the tested joint, if any.
    pub pulse: Option<Pulse>,
    /// Duration [s].
    pub duration_s: f64,
}

/// The on-policy runs of tested joint `joint` around `kp_per_s2`: the two-joint rounds'
/// [`super::onpolicy::varied_runs`] of its test sine, the holds at the sine's centre with its
/// disturbance pulse; the first `runs` (at most six), `periods` sine periods each.
pub fn leg_record_plans(
    cfg: &LegSuiteConfig,
    joint: usize,
    kp_per_s2: f64,
    runs: usize,
    periods: f64,
) -> Vec<LegRecordPlan> {
    let Some(tj) = cfg.joints.get(joint) else {
        return vec![];
    };
    super::onpolicy::varied_runs(
        tj.sine,
        centre(&tj.sine),
        tj.pulse,
        kp_per_s2,
        runs,
        periods,
    )
    .into_iter()
    .map(|r| LegRecordPlan {
        joint,
        reference: r.reference,
        kp_per_s2: r.kp_per_s2,
        pulse: r.pulse,
        duration_s: r.duration_s,
    })
    .collect()
}

/// Runs every plan with `cfg.models[model]` compensating (the rest of the leg holding, as in
/// [`run_leg_suite`]); returns every leg joint's trace per plan, in plan order.
pub fn record_leg(
    cfg: &LegSuiteConfig,
    model: usize,
    plans: &[LegRecordPlan],
) -> Result<Vec<Vec<JointTrace>>, ExperimentError> {
    super::session::install_signal_flag()?;
    let leg = LegSetup::load(&cfg.sets)?;
    if model >= cfg.models.len() {
        return Err(ExperimentError::JointIndex(model));
    }
    let trials: Vec<LegTrial> = plans
        .iter()
        .map(|p| {
            let name = &cfg
                .joints
                .get(p.joint)
                .ok_or(ExperimentError::JointIndex(p.joint))?
                .name;
            Ok(LegTrial {
                tested: leg.index(name)?,
                model,
                kp_per_s2: p.kp_per_s2,
                reference: p.reference,
                pulse: p.pulse,
                duration_s: p.duration_s,
            })
        })
        .collect::<Result<_, ExperimentError>>()?;
    let results = run_parallel(cfg.jobs.max(1), &trials, |t| run_one(cfg, &leg, t));
    // The first failure is the error; runs after it did not start.
    let mut out = Vec::with_capacity(results.len());
    let mut skipped = false;
    for r in results {
        match r {
            Some(r) => out.push(r?),
            None => skipped = true,
        }
    }
    if skipped {
        return Err(ExperimentError::Interrupted);
    }
    Ok(out)
}

impl LegSuiteReport {
    /// A Markdown table: one row per (joint, model) with the minimum K_p and the disturbance metrics.
    pub fn markdown(&self) -> String {
        let rest = match self.rest {
            RestMotion::Hold => "hold their pose".to_owned(),
            RestMotion::Sines {
                amplitude_rad,
                freq_hz,
            } => format!("move on sines of {amplitude_rad} rad at {freq_hz} Hz"),
        };
        let mut s = format!(
            "# Whole-leg closed loop\n\nThe other joints {rest} (K_p {} 1/s²), K_d {} 1/s, \
             criterion RMSE ≤ {} × amplitude after {} period(s); seed {}; {} trials in {:.0} s.\n\n\
             | joint | model | min K_p [1/s²] | disturbance K_p | RMSE after release [mrad] | max deflection [mrad] | rest max error [mrad] |\n\
             |---|---|---|---|---|---|---|\n",
            self.rest_kp_per_s2,
            self.kd_per_s,
            self.criterion.frac_of_amplitude,
            self.criterion.skip_periods,
            self.seed,
            self.trials,
            self.wall_s
        );
        for (joint, jr) in &self.joints {
            for (model, c) in &jr.models {
                s.push_str(&format!(
                    "| {joint} | {model} | {} | {} | {:.2} | {:.2} | {:.2} |\n",
                    c.min_kp.display(),
                    c.disturbance_kp_per_s2,
                    c.disturbance.rmse_after_release_rad * 1e3,
                    c.disturbance.max_deflection_rad * 1e3,
                    c.rest_max_abs_err_rad * 1e3
                ));
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn joint(name: &str, index: usize, model: &str) -> String {
        format!(
            "[[joint]]\nname = \"{name}\"\nindex = {index}\ngear_ratio = 100.0\nkt = 0.1\n\
             max_curr = 5.0\n{model}\n"
        )
    }

    /// The on-policy sines vary the test sine's amplitude, frequency and gain, none is the test
    /// sine itself, and each lasts the asked periods; two holds carry the joint's pulse, both signs.
    #[test]
    fn leg_record_plans_vary_the_test_sine_around_the_gain() {
        let cfg = LegSuiteConfig::paper(
            Binaries {
                frictl: "frictl".into(),
                frictiond: "frictiond".into(),
            },
            vec![],
        );
        let Reference::Sine {
            centre_rad,
            amplitude_rad,
            freq_hz,
        } = cfg.joints[0].sine
        else {
            panic!("the knee's test reference is a sine")
        };
        let plans = leg_record_plans(&cfg, 0, 400.0, 6, 3.0);
        assert_eq!(plans.len(), 6, "{plans:?}");
        let pulses: Vec<f64> = plans
            .iter()
            .filter_map(|p| p.pulse.map(|q| q.torque_nm))
            .collect();
        assert_eq!(pulses, [15.0, -15.0], "{plans:?}");
        assert!(leg_record_plans(&cfg, 0, 400.0, 2, 3.0)[1].pulse.is_some());
        for p in plans.iter().filter(|p| p.pulse.is_none()) {
            let Reference::Sine {
                centre_rad: c,
                amplitude_rad: a,
                freq_hz: f,
            } = p.reference
            else {
                panic!("{p:?}")
            };
            assert_eq!((p.joint, c), (0, centre_rad));
            assert!(a != amplitude_rad || f != freq_hz, "{p:?}");
            assert!((p.duration_s * f - 3.0).abs() < 1e-9, "{p:?}");
            assert!((280.0..=800.0).contains(&p.kp_per_s2), "{p:?}");
        }
        assert!(leg_record_plans(&cfg, 5, 400.0, 4, 3.0).is_empty());
    }

    #[test]
    fn a_daemon_config_gives_each_leg_joint_its_model_by_name() {
        let leg = LegSetup::load(&[]).unwrap();
        let dir = std::env::temp_dir().join(format!("legmodel_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let head = "[backend]\nkind = \"shm\"\nservice_prefix = \"t\"\n\n";
        let scv = "friction_model = \"coulomb_viscous_stribeck\"\nkc = 1.0\nka = 50.0\nkv = 0.5\n\
                   ks = 2.0\nvs = 0.1\nalpha = 1.0";
        let cv = "friction_model = \"coulomb_viscous\"\nkc = 3.0\nka = 50.0\nkv = 0.25";
        let law =
            "kfc = 0.6\nlpf = { order = 2, cutoff_hz = 20.0 }\ndelta_theta_offset_motor_rad = 0.25";
        let text = format!(
            "{head}{}{}{}",
            joint("l_ankle_roll", 0, cv),
            joint("l_knee", 1, &format!("{scv}\n{law}")),
            joint("r_knee", 2, cv)
        );
        let path = dir.join("ok.toml");
        std::fs::write(&path, text).unwrap();
        let m = LegModel::from_daemon_config("mine", &path, &leg).unwrap();
        assert_eq!(m.label, "mine");
        assert_eq!(m.per_joint.len(), leg.dof());
        let knee = leg.index("l_knee").unwrap();
        let ankle = leg.index("l_ankle_roll").unwrap();
        assert!(matches!(m.per_joint[knee], FrictionModel::Scv(p) if p.ks == 2.0));
        assert!(matches!(m.per_joint[ankle], FrictionModel::Cv(p) if p.kc == 3.0));
        for (i, f) in m.per_joint.iter().enumerate() {
            if i != knee && i != ankle {
                assert_eq!(*f, FrictionModel::None, "joint {i}");
            }
        }
        // each listed joint's law as the config has it (the knee is payload index 3: beyond the
        // single-joint suite's two), the unlisted ones the shipped law's
        assert_eq!(m.kfc[knee], Some(0.6));
        assert_eq!(
            m.lpf[knee],
            Some(Lpf::Butterworth {
                order: 2,
                cutoff_hz: 20.0
            })
        );
        assert_eq!(m.delta_theta_offset_motor_rad[knee], Some(0.25));
        assert_eq!((m.kfc[ankle], m.lpf[ankle]), (Some(1.0), Some(Lpf::Off)));
        assert_eq!(m.delta_theta_offset_motor_rad[ankle], None);
        let hip = leg.index("l_hip_pitch").unwrap();
        assert_eq!((m.kfc[hip], m.lpf[hip]), (None, None));
        // LuGre is refused, naming the file and the joint
        let lugre = "friction_model = \"lugre\"\nkc = 1.0\nkv = 0.5\nks = 2.0\nvs = 0.1\n\
                     alpha = 1.0\nsigma0 = 1e4\nsigma1 = 10.0";
        let bad = dir.join("lugre.toml");
        std::fs::write(&bad, format!("{head}{}", joint("l_hip_yaw", 0, lugre))).unwrap();
        let e = LegModel::from_daemon_config("x", &bad, &leg).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("lugre.toml") && msg.contains("l_hip_yaw"),
            "{msg}"
        );
        // a file that does not exist: an error naming it, no panic
        let e = LegModel::from_daemon_config("x", &dir.join("none.toml"), &leg).unwrap_err();
        assert!(e.to_string().contains("none.toml"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn unknown_tested_joints_and_short_model_lists_are_errors() {
        let leg = LegSetup::load(&[]).unwrap();
        assert!(matches!(
            leg.index("r_knee"),
            Err(ExperimentError::LegJoint(n)) if n == "r_knee"
        ));
        let bins = Binaries {
            frictl: "/nonexistent/frictl".into(),
            frictiond: "/nonexistent/frictiond".into(),
        };
        let cfg = LegSuiteConfig::paper(bins, vec![LegModel::uniform(FrictionModel::None, 2)]);
        let e = run_leg_suite(&cfg).unwrap_err();
        assert!(
            matches!(
                e,
                ExperimentError::LegModels {
                    got: 2,
                    expected: 6,
                    ..
                }
            ),
            "{e}"
        );
    }
}

//! `frictl experiment track|min-kp|disturbance|all|record` — the paper's closed-loop experiments on
//! the virtual joints, through real processes: the plant (`frictl sim serve`) and `frictiond` as
//! child processes, the computed-torque controller in this process (see `frictionless_experiment`).
//! `record` runs varied closed-loop runs with a model compensating and writes them as acquisition
//! logs for `frictl preprocess` (on-policy data, see `frictionless_experiment::onpolicy`).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use frictionless_dataset::fit_file::FittedModel;
use frictionless_experiment::controller::PAPER_KD_PER_S;
use frictionless_experiment::metrics::TrackCriterion;
use frictionless_experiment::report::{SuiteReport, slug, write_trace_csv};
use frictionless_experiment::rig::JointSetup;
use frictionless_experiment::run::{JointTrace, Pulse};
use frictionless_experiment::session::{
    Binaries, FrictionModel, LawSettings, Lpf, Mode, install_signal_flag,
};
use frictionless_experiment::suite::{self, SuiteConfig, Task};

pub use frictl_cli::experiment::*;

/// Parses `--lpf` into per-joint overrides (`None` = shipped); a cut-off keeps the shipped order
/// (2 if the shipped config has no LPF).
fn lpf_overrides(spec: &str, names: &[String; 2]) -> anyhow::Result<[Option<Lpf>; 2]> {
    let parts = per_joint("lpf", spec, &[0, 1], true)?;
    let mut out = [None; 2];
    for j in 0..2 {
        let Some(v) = &parts[j] else { continue };
        out[j] = Some(match v.as_str() {
            "off" | "none" => Lpf::Off,
            t => {
                let cutoff_hz = t
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite() && *x > 0.0 && *x < 500.0)
                    .with_context(|| {
                        format!(
                            "--lpf `{spec}`: `{t}` for {} is neither `off` nor a cut-off in (0, 500) Hz",
                            names[j]
                        )
                    })?;
                let order = match LawSettings::shipped(&names[j], None, None)?.lpf {
                    Lpf::Butterworth { order, .. } => order,
                    Lpf::Off => 2,
                };
                Lpf::Butterworth { order, cutoff_hz }
            }
        });
    }
    Ok(out)
}

/// Parses `--pinn-delta-theta-offset` into per-joint offsets (`None` = latch at enable).
fn pinn_offsets(spec: &str) -> anyhow::Result<[Option<f64>; 2]> {
    let one = |v: &str| -> anyhow::Result<Option<f64>> {
        match v.trim() {
            "enable" => Ok(None),
            t => t
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .map(Some)
                .with_context(|| {
                    format!(
                        "--pinn-delta-theta-offset: `{t}` is neither `enable` nor a finite number"
                    )
                }),
        }
    };
    let parts = per_joint("pinn-delta-theta-offset", spec, &[0, 1], true)?;
    let mut out = [Some(0.0); 2];
    for j in 0..2 {
        if let Some(v) = &parts[j] {
            out[j] = one(v)?;
        }
    }
    Ok(out)
}

const JOINT_KEYS: [[&str; 2]; 2] = [["knee", "l_knee"], ["ankle_roll", "l_ankle_roll"]];

/// Parses `v` or `knee=v,ankle_roll=w` into per-joint strings for the selected `joints`.
fn per_joint(
    what: &str,
    spec: &str,
    joints: &[usize],
    allow_shared: bool,
) -> anyhow::Result<[Option<String>; 2]> {
    let mut out: [Option<String>; 2] = [None, None];
    if !spec.contains('=') {
        if joints.len() > 1 && !allow_shared {
            bail!("--{what} `{spec}`: give one per joint, e.g. knee=A,ankle_roll=B");
        }
        for &j in joints {
            out[j] = Some(spec.to_owned());
        }
        return Ok(out);
    }
    for part in spec.split(',') {
        let (k, v) = part
            .split_once('=')
            .with_context(|| format!("--{what} `{spec}`: `{part}` is not JOINT=VALUE"))?;
        let j = JOINT_KEYS
            .iter()
            .position(|names| names.contains(&k.trim()))
            .with_context(|| {
                format!("--{what} `{spec}`: unknown joint `{k}` (knee, ankle_roll)")
            })?;
        out[j] = Some(v.trim().to_owned());
    }
    Ok(out)
}

fn per_joint_f64(what: &str, spec: &str, joints: &[usize]) -> anyhow::Result<[Option<f64>; 2]> {
    let s = per_joint(what, spec, joints, true)?;
    let mut out = [None, None];
    for j in 0..2 {
        if let Some(v) = &s[j] {
            out[j] = Some(
                v.parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite() && *x > 0.0)
                    .with_context(|| format!("--{what}: `{v}` is not a positive number"))?,
            );
        }
    }
    Ok(out)
}

/// Runs `frictl experiment`.
pub fn run(args: Args) -> anyhow::Result<()> {
    install_signal_flag()?;
    if args.robot == RobotSel::Leg {
        return run_leg(&args);
    }
    anyhow::ensure!(
        args.leg_config.is_empty(),
        "--leg-config {}: only with --robot leg (the single joints take --cv/--scv/--pinn)",
        args.leg_config.join(",")
    );
    let started = std::time::Instant::now();
    let joints: Vec<usize> = match args.joint {
        JointSel::Knee => vec![0],
        JointSel::AnkleRoll => vec![1],
        JointSel::Both => vec![0, 1],
    };
    let mode = if args.realtime {
        Mode::Realtime
    } else {
        Mode::Lockstep
    };
    anyhow::ensure!(
        args.criterion_frac > 0.0 && args.periods > args.skip_periods && args.skip_periods >= 0.0,
        "need --criterion-frac > 0 and --periods > --skip-periods ≥ 0"
    );
    let models = load_models(&args, &joints)?;
    let setups = JointSetup::both(&args.sets)?;
    let names = [
        setups[0].params.joint.clone(),
        setups[1].params.joint.clone(),
    ];
    let cfg = suite_config(&args, &joints, mode, &names)?;
    let kp_given = args
        .kp
        .as_deref()
        .map(|s| per_joint_f64("kp", s, &joints))
        .transpose()?;
    let mut suite = Suite {
        bins: Binaries::locate()?,
        report: SuiteReport {
            mode: if mode == Mode::Lockstep {
                "lockstep"
            } else {
                "realtime"
            }
            .into(),
            seed: args.seed,
            kd_per_s: PAPER_KD_PER_S,
            ..SuiteReport::default()
        },
        setups,
        cfg,
        models,
        joints,
        names,
        traces: vec![],
        trials: 0,
    };
    suite.describe_setup()?;
    std::fs::create_dir_all(args.out.join("traces"))
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    match (args.kind, kp_given) {
        (Kind::Track, kp) => {
            let kp = kp.unwrap_or([None, None]);
            let kp = [kp[0].unwrap_or(30.0), kp[1].unwrap_or(550.0)];
            suite.track(&|j, _| kp[j], "track", false, "track")?;
        }
        (Kind::Record, kp) => {
            let kp = kp.context("record needs --kp (the gain the runs vary around)")?;
            record(&args, &suite, kp)?;
            return Ok(());
        }
        (Kind::Disturbance, Some(kp)) => {
            let kp = [kp[0].unwrap_or(30.0), kp[1].unwrap_or(550.0)];
            for &j in &suite.joints {
                let name = suite.names[j].clone();
                suite.report.pulses.insert(name.clone(), suite.cfg.pulse[j]);
                suite.report.low_kp_source.insert(name, "--kp".into());
            }
            suite.disturbance(&|j, _| kp[j], "disturbance", true, "disturbance")?;
        }
        (kind, _) => {
            if !args.quiet {
                eprintln!(
                    "min-kp: criterion RMSE ≤ {} × amplitude",
                    args.criterion_frac
                );
            }
            let own = suite.min_kp()?;
            if kind != Kind::MinKp {
                suite.at_own_and_low_kp(&own, kind == Kind::All)?;
            }
        }
    }
    suite.report.trials = suite.trials;
    suite.report.wall_s = started.elapsed().as_secs_f64();
    write_outputs(&args, &suite.report, &suite.traces)
}

/// `frictl experiment record`: the on-policy runs of every selected joint, their logs and
/// `record.json`.
fn record(args: &Args, suite: &Suite, kp: [Option<f64>; 2]) -> anyhow::Result<()> {
    use frictionless_experiment::metrics;
    use frictionless_experiment::onpolicy;
    for &j in &suite.joints {
        let n = suite.models.iter().filter(|(i, _)| *i == j).count();
        anyhow::ensure!(
            n == 1,
            "record runs one model per joint; {} has {n} (pass --model)",
            suite.names[j]
        );
    }
    let mut plans = vec![];
    for &j in &suite.joints {
        let kp = kp[j].with_context(|| format!("--kp: no gain for {}", suite.names[j]))?;
        plans.extend(onpolicy::plans(j, kp, args.record_runs, args.periods));
    }
    let traces = onpolicy::record(
        &suite.bins,
        &suite.setups,
        &suite.cfg,
        &suite.models,
        &plans,
    )?;
    let mut summary = serde_json::Map::new();
    for &j in &suite.joints {
        let runs: Vec<(&onpolicy::RecordPlan, &JointTrace)> = plans
            .iter()
            .zip(&traces)
            .filter(|(p, _)| p.index == j)
            .collect();
        let csv = args.out.join(format!("{}_onpolicy.csv", suite.names[j]));
        let per_run: Vec<serde_json::Value> = runs
            .iter()
            .map(|(p, t)| {
                let m = metrics::track(t, 1.0, f64::INFINITY);
                serde_json::json!({
                    "plan": p,
                    "tau_f_rmse_nm": m.friction_est_rmse_nm,
                    "tracking_rmse_rad": m.rmse_rad,
                })
            })
            .collect();
        let model = suite
            .models
            .iter()
            .find(|(i, _)| *i == j)
            .map_or("", |(_, m)| m.label());
        let rows = onpolicy::write_raw_log(
            &csv,
            &suite.setups[j],
            &runs.iter().map(|(_, t)| *t).collect::<Vec<_>>(),
            args.seed,
            serde_json::json!({ "model": model, "runs": per_run }),
        )?;
        eprintln!(
            "frictl experiment record: {} ({model}) {} runs, {rows} rows -> {}",
            suite.names[j],
            runs.len(),
            csv.display()
        );
        summary.insert(
            suite.names[j].clone(),
            serde_json::json!({ "model": model, "csv": csv.display().to_string(), "runs": per_run }),
        );
    }
    let path = args.out.join("record.json");
    frictionless::output_file::write(&path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

/// The friction model of every (joint, `--model`) pair, loaded from the `--cv` / `--scv` / `--pinn`
/// files (default models: none plus every one a file was given for).
fn load_models(args: &Args, joints: &[usize]) -> anyhow::Result<Vec<(usize, FrictionModel)>> {
    let cv = args
        .cv
        .as_deref()
        .map(|s| per_joint("cv", s, joints, false))
        .transpose()?;
    let scv = args
        .scv
        .as_deref()
        .map(|s| per_joint("scv", s, joints, false))
        .transpose()?;
    let pinn = args
        .pinn
        .as_deref()
        .map(|s| per_joint("pinn", s, joints, false))
        .transpose()?;
    let wanted: Vec<ModelSel> = match &args.model {
        Some(m) => m.clone(),
        None => {
            let mut m = vec![ModelSel::None];
            if cv.is_some() {
                m.push(ModelSel::Cv);
            }
            if scv.is_some() {
                m.push(ModelSel::Scv);
            }
            if pinn.is_some() {
                m.push(ModelSel::Pinn);
            }
            m
        }
    };
    anyhow::ensure!(
        !(args.realtime && wanted.contains(&ModelSel::Oracle)),
        "--model oracle runs in lockstep only (it adds the true friction of the state each request \
         answers); drop --realtime or the oracle"
    );
    let mut models: Vec<(usize, FrictionModel)> = vec![];
    for &j in joints {
        let name = JOINT_KEYS[j][0];
        for m in &wanted {
            let missing = |flag: &str| {
                anyhow::anyhow!("--model {m:?} for {name} needs --{flag} with a file for {name}")
            };
            let fm = match m {
                ModelSel::None => FrictionModel::None,
                ModelSel::Cv => FrictionModel::Cv(FittedModel::read_cv(Path::new(
                    cv.as_ref()
                        .and_then(|c| c[j].as_ref())
                        .ok_or_else(|| missing("cv"))?,
                ))?),
                ModelSel::Scv => FrictionModel::Scv(FittedModel::read_scv(Path::new(
                    scv.as_ref()
                        .and_then(|c| c[j].as_ref())
                        .ok_or_else(|| missing("scv"))?,
                ))?),
                ModelSel::Pinn => {
                    let p = PathBuf::from(
                        pinn.as_ref()
                            .and_then(|c| c[j].as_ref())
                            .ok_or_else(|| missing("pinn"))?,
                    );
                    anyhow::ensure!(p.is_file(), "--pinn: {} is not a file", p.display());
                    FrictionModel::Pinn(p)
                }
                ModelSel::Oracle => FrictionModel::Oracle,
            };
            models.push((j, fm));
        }
    }
    Ok(models)
}

/// The suite's settings from the flags: K_p search ranges, disturbance pulses, criterion, kfc / LPF
/// overrides, the PINN's Δθ offsets.
fn suite_config(
    args: &Args,
    joints: &[usize],
    mode: Mode,
    names: &[String; 2],
) -> anyhow::Result<SuiteConfig> {
    let mut kp_range = [(3.0, 3000.0), (30.0, 100000.0)];
    if let Some(s) = &args.kp_range {
        let r = per_joint("kp-range", s, joints, true)?;
        for j in 0..2 {
            if let Some(v) = &r[j] {
                let (a, b) = v
                    .split_once(':')
                    .with_context(|| format!("--kp-range: `{v}` is not LO:HI"))?;
                kp_range[j] = (
                    a.parse().with_context(|| format!("--kp-range: `{a}`"))?,
                    b.parse().with_context(|| format!("--kp-range: `{b}`"))?,
                );
            }
        }
    }
    let mut pulse_nm = [15.0, 5.0];
    if let Some(s) = &args.pulse_nm {
        let p = per_joint_f64("pulse-nm", s, joints)?;
        for j in 0..2 {
            if let Some(v) = p[j] {
                pulse_nm[j] = v;
            }
        }
    }
    let pulse = |j: usize| Pulse {
        start_s: args.hold_s,
        duration_s: args.pulse_s,
        torque_nm: pulse_nm[j],
    };
    let lpf = match &args.lpf {
        Some(s) => lpf_overrides(s, names)?,
        None => [None; 2],
    };
    Ok(SuiteConfig {
        mode,
        seed: args.seed,
        sets: args.sets.clone(),
        criterion: TrackCriterion {
            frac_of_amplitude: args.criterion_frac,
            skip_periods: args.skip_periods,
        },
        periods: args.periods,
        kp_range,
        iterations: args.iterations,
        pulse: [pulse(0), pulse(1)],
        after_release_s: args.after_release_s,
        progress: !args.quiet,
        pinn_delta_theta_offset_motor_rad: pinn_offsets(&args.pinn_delta_theta_offset)?,
        kfc: match &args.kfc {
            Some(s) => per_joint_f64("kfc", s, &[0, 1])?,
            None => [None; 2],
        },
        lpf,
        rotor_inertia_in_m: args.controller_inertia == ControllerInertia::LinkRotor,
        jobs: match (mode, args.jobs) {
            (_, Some(0)) => anyhow::bail!("--jobs 0: at least one trial must run"),
            (Mode::Realtime, Some(j)) if j > 1 => {
                anyhow::bail!("--jobs {j}: real-time trials run one at a time (lockstep only)")
            }
            (_, Some(j)) => j,
            (_, None) => std::thread::available_parallelism().map_or(1, |n| n.get()),
        },
    })
}

/// One `frictl experiment` run: what its trial batches share and what they accumulate.
struct Suite {
    bins: Binaries,
    setups: [JointSetup; 2],
    cfg: SuiteConfig,
    /// (joint index, model) of every task.
    models: Vec<(usize, FrictionModel)>,
    joints: Vec<usize>,
    /// Joint names by index.
    names: [String; 2],
    report: SuiteReport,
    /// (name, trace) of every trial kept for the CSVs and plots.
    traces: Vec<(String, JointTrace)>,
    trials: usize,
}

impl Suite {
    /// Every task at the gain `kp(joint, model label)`.
    fn tasks_at(&self, kp: &dyn Fn(usize, &str) -> f64) -> Vec<Task> {
        self.models
            .iter()
            .map(|(j, m)| Task {
                index: *j,
                model: m.clone(),
                kp_per_s2: kp(*j, m.label()),
            })
            .collect()
    }

    /// The report's reference and frictiond-law description per joint.
    fn describe_setup(&mut self) -> anyhow::Result<()> {
        for &j in &self.joints {
            let desc = match suite::sine(j) {
                frictionless_experiment::controller::Reference::Sine {
                    centre_rad,
                    amplitude_rad,
                    freq_hz,
                } => format!("s_d = {centre_rad} − {amplitude_rad}·cos(2π·{freq_hz}·t) rad"),
                r => format!("{r:?}"),
            };
            self.report.references.insert(self.names[j].clone(), desc);
            let law = LawSettings::shipped(&self.names[j], self.cfg.kfc[j], self.cfg.lpf[j])?;
            let m = if self.cfg.rotor_inertia_in_m {
                format!(
                    "; controller M = I_L + r²J_m ({:.4} kg·m² added)",
                    self.setups[j].params.j_eq_kgm2()
                )
            } else {
                String::new()
            };
            self.report
                .configuration
                .insert(self.names[j].clone(), format!("{}{m}", law.describe()));
        }
        Ok(())
    }

    /// Tracking trials of every task at `kp`; traces named `{prefix}_{joint}_{model}`.
    fn track(
        &mut self,
        kp: &dyn Fn(usize, &str) -> f64,
        label: &str,
        at_low_kp: bool,
        prefix: &str,
    ) -> anyhow::Result<()> {
        let rs = suite::track(
            &self.bins,
            &self.setups,
            &self.cfg,
            &self.tasks_at(kp),
            label,
        )?;
        self.trials += rs.len();
        self.report.add_track(&self.names, &rs, at_low_kp);
        for r in rs {
            self.traces.push((
                format!("{prefix}_{}_{}", self.names[r.index], r.model),
                r.trace,
            ));
        }
        Ok(())
    }

    /// Disturbance trials of every task at `kp`; traces named `{prefix}_{joint}_{model}`.
    fn disturbance(
        &mut self,
        kp: &dyn Fn(usize, &str) -> f64,
        label: &str,
        at_low_kp: bool,
        prefix: &str,
    ) -> anyhow::Result<()> {
        let rs = suite::disturbance(
            &self.bins,
            &self.setups,
            &self.cfg,
            &self.tasks_at(kp),
            label,
        )?;
        self.trials += rs.len();
        self.report.add_disturbance(&self.names, &rs, at_low_kp);
        for r in rs {
            self.traces.push((
                format!("{prefix}_{}_{}", self.names[r.index], r.model),
                r.trace,
            ));
        }
        Ok(())
    }

    /// The minimum-K_p search of every task; returns (joint, model label, K_p to run at).
    fn min_kp(&mut self) -> anyhow::Result<Vec<(usize, String, f64)>> {
        self.report.criterion = Some(self.cfg.criterion);
        let rs = suite::min_kp(
            &self.bins,
            &self.setups,
            &self.cfg,
            &self.tasks_at(&|_, _| 0.0),
        )?;
        self.trials += rs.iter().map(|r| r.steps.len()).sum::<usize>();
        self.report.add_min_kp(&self.names, &rs);
        for r in &rs {
            if let Some(t) = &r.at_min {
                self.traces.push((
                    format!("track_min_kp_{}_{}", self.names[r.index], r.model),
                    t.trace.clone(),
                ));
            }
        }
        Ok(rs
            .iter()
            .map(|r| (r.index, r.model.clone(), r.min_kp.kp_for_runs()))
            .collect())
    }

    /// After the search: disturbance at each model's own minimum K_p, then disturbance (and with
    /// `track`, tracking) at the common low gain ([`Suite::low_kp`]).
    fn at_own_and_low_kp(
        &mut self,
        own: &[(usize, String, f64)],
        track: bool,
    ) -> anyhow::Result<()> {
        for &j in &self.joints {
            self.report
                .pulses
                .insert(self.names[j].clone(), self.cfg.pulse[j]);
        }
        let own_kp = |j: usize, m: &str| {
            own.iter()
                .find(|(i, l, _)| *i == j && l == m)
                .map_or(f64::NAN, |x| x.2)
        };
        self.disturbance(&own_kp, "disturbance @ own K_p", false, "disturbance_own")?;
        let low = self.low_kp(own)?;
        self.disturbance(
            &|j, _| low[j],
            "disturbance @ low K_p",
            true,
            "disturbance_low",
        )?;
        if track {
            self.track(&|j, _| low[j], "track @ low K_p", true, "track_low")?;
        }
        Ok(())
    }

    /// The common low gain per joint: the PINN's minimum K_p, else the lowest of the models run
    /// (recorded in the report's `low_kp_source`).
    fn low_kp(&mut self, own: &[(usize, String, f64)]) -> anyhow::Result<[f64; 2]> {
        let mut low = [f64::NAN; 2];
        for &j in &self.joints {
            let pinn = own.iter().find(|(i, l, _)| *i == j && l == "PINN");
            let (src, kp) = match pinn {
                Some(p) => ("PINN".to_owned(), p.2),
                None => {
                    let m = own
                        .iter()
                        .filter(|(i, _, _)| *i == j)
                        .min_by(|a, b| a.2.total_cmp(&b.2))
                        .context("no model ran")?;
                    (format!("{} (no PINN run)", m.1), m.2)
                }
            };
            low[j] = kp;
            self.report.low_kp_source.insert(
                self.names[j].clone(),
                format!("{src}, K_p {}", frictionless_experiment::search::sig3(kp)),
            );
        }
        Ok(low)
    }
}

/// Traces (CSV), plots, `tables.md` and `report.json` (and `--json`).
fn write_outputs(
    args: &Args,
    report: &SuiteReport,
    traces: &[(String, JointTrace)],
) -> anyhow::Result<()> {
    for (name, tr) in traces {
        write_trace_csv(
            &args.out.join("traces").join(format!("{}.csv", slug(name))),
            tr,
        )?;
    }
    if !args.no_plots {
        frictionless_experiment::report::write_plots(&args.out, traces)?;
    }
    let md = report.markdown();
    println!("{md}");
    frictionless::output_file::write(args.out.join("tables.md"), &md)?;
    let json = serde_json::to_string_pretty(report)?;
    frictionless::output_file::write(args.out.join("report.json"), &json)?;
    if let Some(p) = &args.json {
        frictionless::output_file::write(p, &json)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    eprintln!(
        "frictl experiment: {} trials in {:.1} s; tables, report.json and traces in {}",
        report.trials,
        report.wall_s,
        args.out.display()
    );
    Ok(())
}

/// `frictl experiment all --robot leg`: parses the options into a [`LegSuiteConfig`], runs
/// [`run_leg_suite`] and writes `leg-tables.md` and `leg-report.json`.
fn run_leg(args: &Args) -> anyhow::Result<()> {
    use frictionless_experiment::leg::{LegModel, LegSuiteConfig, RestMotion, run_leg_suite};
    use frictionless_experiment::rig::LegSetup;
    anyhow::ensure!(
        args.kind == Kind::All,
        "--robot leg runs `all` (min-K_p and disturbance), not `{}`",
        clap::ValueEnum::to_possible_value(&args.kind)
            .map_or_else(String::new, |v| v.get_name().to_owned())
    );
    anyhow::ensure!(!args.realtime, "--robot leg runs in lockstep only");
    // Options of the single joints are refused, not ignored.
    anyhow::ensure!(
        args.joint == JointSel::Both,
        "--joint with --robot leg: the leg suite tests its knee and ankle roll (no --joint)"
    );
    if let Some(m) = args
        .model
        .as_ref()
        .and_then(|m| m.iter().find(|m| **m != ModelSel::Oracle))
    {
        anyhow::bail!(
            "--model {} with --robot leg: the leg's compensations are --leg-config LABEL=FILE \
             (--model takes only `oracle` there)",
            clap::ValueEnum::to_possible_value(m)
                .map_or_else(String::new, |v| v.get_name().to_owned())
        );
    }
    for (flag, v) in [
        ("--cv", &args.cv),
        ("--scv", &args.scv),
        ("--pinn", &args.pinn),
    ] {
        anyhow::ensure!(
            v.is_none(),
            "{flag} with --robot leg: the leg's compensations are --leg-config LABEL=FILE"
        );
    }
    // The outputs, before the run: the directory exists or is created, and every file is writable.
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("--out {}: cannot create", args.out.display()))?;
    let tables = args.out.join("leg-tables.md");
    let report_path = args.out.join("leg-report.json");
    let mut outputs: Vec<&Path> = vec![&tables, &report_path];
    outputs.extend(args.json.as_deref());
    let configs: Vec<&Path> = args
        .leg_config
        .iter()
        .filter_map(|i| i.split_once('=').map(|(_, f)| Path::new(f)))
        .collect();
    super::check_outputs(&configs, &outputs)?;
    let probe = args.out.join(format!(".write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("--out {}: not writable", args.out.display()))?;
    let _ = std::fs::remove_file(&probe);
    anyhow::ensure!(
        args.criterion_frac > 0.0 && args.periods > args.skip_periods && args.skip_periods >= 0.0,
        "need --criterion-frac > 0 and --periods > --skip-periods ≥ 0"
    );
    let leg = LegSetup::load(&args.sets)?;
    let n = leg.dof();
    let mut models = vec![LegModel::uniform(FrictionModel::None, n)];
    for item in &args.leg_config {
        let (label, file) = item
            .split_once('=')
            .with_context(|| format!("--leg-config {item:?}: expected LABEL=FILE"))?;
        // Each label is one row of the report: not empty, not a built-in row, not repeated.
        let label = label.trim();
        anyhow::ensure!(
            !label.is_empty() && !file.is_empty(),
            "--leg-config {item:?}: expected LABEL=FILE with a non-empty label and file"
        );
        anyhow::ensure!(
            !["none", "oracle"].contains(&label),
            "--leg-config {item:?}: `{label}` is the label of a built-in row (no compensation, the \
             oracle); name the config's row otherwise"
        );
        anyhow::ensure!(
            !models.iter().any(|m| m.label == label),
            "--leg-config {item:?}: the label `{label}` is given twice (each is one row of the report)"
        );
        models.push(LegModel::from_daemon_config(label, Path::new(file), &leg)?);
    }
    if args
        .model
        .as_ref()
        .is_some_and(|m| m.contains(&ModelSel::Oracle))
    {
        models.push(LegModel::uniform(FrictionModel::Oracle, n));
    }
    let mut cfg = LegSuiteConfig::paper(Binaries::locate()?, models);
    cfg.seed = args.seed;
    cfg.sets = args.sets.clone();
    cfg.criterion = TrackCriterion {
        frac_of_amplitude: args.criterion_frac,
        skip_periods: args.skip_periods,
    };
    cfg.periods = args.periods;
    cfg.iterations = args.iterations;
    cfg.after_release_s = args.after_release_s;
    cfg.rest_kp_per_s2 = args.rest_kp;
    if let Some(a) = args.rest_sine_rad {
        cfg.rest = RestMotion::Sines {
            amplitude_rad: a,
            freq_hz: 0.3,
        };
    }
    cfg.rotor_inertia_in_m = args.controller_inertia == ControllerInertia::LinkRotor;
    cfg.jobs = args
        .jobs
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    cfg.progress = !args.quiet;
    let report = run_leg_suite(&cfg)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let md = report.markdown();
    println!("{md}");
    frictionless::output_file::write(args.out.join("leg-tables.md"), &md)?;
    let json = serde_json::to_string_pretty(&report)?;
    frictionless::output_file::write(args.out.join("leg-report.json"), &json)?;
    if let Some(p) = &args.json {
        frictionless::output_file::write(p, &json)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    eprintln!(
        "frictl experiment --robot leg: {} trials in {:.1} s; leg-tables.md and leg-report.json in {}",
        report.trials,
        report.wall_s,
        args.out.display()
    );
    Ok(())
}

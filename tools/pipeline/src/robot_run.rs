//! `frictl robot` — a whole robot from one TOML file (schema: [`crate::robot`]).
//!
//! `frictl robot run ROBOT.toml --out DIR` runs, for every joint, the stages acquire (simulator
//! presets) or preprocess (raw logs) → fit CV and SCV → search (or train) → eval → export ONNX, each as
//! a `frictl` child started in `DIR` with paths relative to it, its output in `DIR/logs/`. Then it
//! writes ONE frictiond config, `DIR/frictiond.toml` (through `frictiond-config`'s types, every joint
//! with its trained PINN), and the per-joint report `DIR/report.json` + `DIR/report.md`.
//!
//! Resumable: a stage is skipped when its stamp (`DIR/joints/J/stamps/STAGE.sha256`: the SHA-256 of
//! its arguments with every input file replaced by the SHA-256 of its content, then the SHA-256 of
//! every output as the stage wrote it) matches: the same inputs, and every output still the file the
//! stage wrote. An output missing or changed since (a damaged file) makes the stage run again, with a
//! line naming the file, so a later stage never runs on it. Stamps name no absolute path, so a joint directory made on another machine (a Ray
//! worker) is recognised. The search stage always passes `--resume`: trials run elsewhere into
//! `DIR/joints/J/search` (`frictl search --only-trials`) are kept and only the missing ones run; a
//! search whose settings changed in the robot file is refused there (remove `DIR/joints/J/search` to
//! start it again).
//!
//! `frictl robot plan ROBOT.toml --out DIR` prints, as JSON, what the Ray driver needs: each joint's
//! directory, its input files, the `frictl search` arguments (relative to `DIR`) and the trial count.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use crate::Host;
use crate::robot::{DataSource, JointSection, RobotFile};
use anyhow::{Context, bail};
use frictiond_config::{
    JointConfig, LpfConfig, ModelKind, OodMode, RawConfig, WarmupName, default_ood_margin,
    default_ood_ramp_ms,
};
use frictionless::features::FeatureSet;
use frictionless_eval::Report as EvalReport;
use frictionless_train::data::DeltaThetaOffset;
use frictionless_train::pipeline::{self, TrainReport};
use frictionless_train::search::{TrialResult, read_results};
use sha2::{Digest, Sha256};

use frictl_cli::robot::{Action, Args, RunArgs, Until};
use frictl_cli::{acquire, eval, export, fit, preprocess, search, stage, train};

/// One `frictl` invocation of a joint's pipeline (paths relative to the output directory).
#[derive(Clone, Debug, serde::Serialize)]
struct Stage {
    /// Stage id (also the stamp's and the log's name).
    id: String,
    /// Where it belongs.
    phase: Until,
    /// `frictl` arguments.
    args: Vec<String>,
    /// Input files (the stamp hashes their content).
    inputs: Vec<String>,
    /// Files that must exist for the stage to count as done.
    outputs: Vec<String>,
}

/// The files of one joint, relative to the output directory.
#[derive(Clone, Debug, serde::Serialize)]
struct JointPlan {
    name: String,
    dir: String,
    /// The PINN's input feature set.
    features: FeatureSet,
    /// Training datasets.
    train: Vec<String>,
    /// Held-out datasets (empty: the evaluation uses the split's test chunks).
    test: Vec<String>,
    cv: String,
    scv: String,
    /// The PINN frictiond runs.
    model: String,
    /// Its train report.
    model_report: String,
    /// The search directory (`null` without a search).
    search_dir: Option<String>,
    /// Trials of the search (0: trained once).
    trials: usize,
    /// `frictl search` arguments without `--out`, `--resume`, `--parallel`, `--threads` (a driver adds
    /// its own).
    search_args: Vec<String>,
    /// Files from outside the output directory the stages read (absolute).
    external_inputs: Vec<String>,
    stages: Vec<Stage>,
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// The stages of one joint.
fn plan_joint(robot: &RobotFile, j: &JointSection) -> anyhow::Result<JointPlan> {
    let mut p = Planner {
        robot,
        j,
        dir: format!("joints/{}", j.name),
        stages: vec![],
        external_inputs: vec![],
    };
    let (train, test) = match j.source() {
        DataSource::Preset => p.acquire_and_label()?,
        DataSource::Logs => p.label_logs()?,
        DataSource::Datasets => p.given_datasets(),
        DataSource::Import => p.import_logs()?,
    };
    let (cv, scv) = p.fits(&train)?;
    let (search_args, model) = p.model(&train, &scv)?;
    p.evaluate(&train, &test, [&cv, &scv], &model)?;
    p.export(&model.fwt)?;
    Ok(JointPlan {
        name: j.name.clone(),
        features: j.features,
        dir: p.dir,
        train,
        test,
        cv,
        scv,
        model: model.fwt,
        model_report: model.report,
        search_dir: model.search_dir,
        trials: robot.search.trials,
        search_args,
        external_inputs: p.external_inputs,
        stages: p.stages,
    })
}

/// The PINN a joint's plan ends with: trained once, or picked by a search.
struct PlannedModel {
    /// The `.fwt` frictiond runs.
    fwt: String,
    /// Its train report.
    report: String,
    /// The search directory (`None`: trained once).
    search_dir: Option<String>,
}

/// One joint's plan while it is built: its stages and the files from outside the output directory
/// they read, in stage order.
struct Planner<'a> {
    robot: &'a RobotFile,
    j: &'a JointSection,
    /// The joint's directory, relative to the output directory.
    dir: String,
    stages: Vec<Stage>,
    external_inputs: Vec<String>,
}

impl Planner<'_> {
    /// `name` in the joint's directory.
    fn f(&self, name: &str) -> String {
        format!("{}/{name}", self.dir)
    }

    /// A preset joint: the protocol (train) and the unseen tracking run (test) recorded on the
    /// virtual robot, each labelled; returns the (train, test) datasets.
    fn acquire_and_label(&mut self) -> anyhow::Result<(Vec<String>, Vec<String>)> {
        let (robot, j) = (self.robot, self.j);
        let seed = robot.robot.seed;
        let mut test_sets: Vec<String> = frictionless_acquire::config::UNSEEN_TEST_RUN
            .map(String::from)
            .into();
        test_sets.extend(robot.acquire.test_set.iter().cloned());
        let acquire_args = |seed: u64, name: &str, sets: Vec<String>| {
            stage::argv(
                &["acquire"],
                &acquire::Args {
                    preset: j.preset.clone().unwrap_or_default(),
                    seed,
                    out: PathBuf::from(&self.dir),
                    name: Some(name.into()),
                    sets,
                    ..stage::defaults()?
                },
            )
        };
        let train_args = acquire_args(seed, "train", robot.acquire.set.clone())?;
        let test_args = acquire_args(seed + 100, "test", test_sets)?;
        for (what, args) in [("train", train_args), ("test", test_args)] {
            let (log, sidecar) = (
                self.f(&format!("{what}.csv")),
                self.f(&format!("{what}.json")),
            );
            let (ds, ds_sidecar) = (
                self.f(&format!("{what}_ds.csv")),
                self.f(&format!("{what}_ds.json")),
            );
            self.stages.push(Stage {
                id: format!("acquire_{what}"),
                phase: Until::Data,
                args,
                inputs: vec![],
                outputs: vec![log.clone(), sidecar.clone()],
            });
            let args = preprocess_argv(
                j,
                preprocess::Args {
                    log: PathBuf::from(&log),
                    out: PathBuf::from(&ds),
                    subtract_reflected_inertia: Some("sidecar".into()),
                    ..stage::defaults()?
                },
            )?;
            self.stages.push(Stage {
                id: format!("preprocess_{what}"),
                phase: Until::Data,
                args,
                inputs: vec![log, sidecar],
                outputs: vec![ds, ds_sidecar],
            });
        }
        Ok((vec![self.f("train_ds.csv")], vec![self.f("test_ds.csv")]))
    }

    /// A joint with recorded logs (`logs`, `test_logs`): each labelled into a dataset (with the
    /// robot's URDF when it names one); returns the (train, test) datasets.
    fn label_logs(&mut self) -> anyhow::Result<(Vec<String>, Vec<String>)> {
        let (robot, j) = (self.robot, self.j);
        let mut lists = (vec![], vec![]);
        for (what, logs) in [("train", &j.logs), ("test", &j.test_logs)] {
            for (i, log) in logs.iter().enumerate() {
                let ds = self.f(&format!("{what}_{i}_ds.csv"));
                let mut base = preprocess::Args {
                    log: log.clone(),
                    out: PathBuf::from(&ds),
                    ..stage::defaults()?
                };
                if let Some(u) = &robot.robot.urdf {
                    base.urdf = Some(s(u));
                    base.joint = Some(j.name.clone());
                    self.external_inputs.push(s(u));
                }
                let args = preprocess_argv(j, base)?;
                let sidecar = s(&log.with_extension("json"));
                self.external_inputs.extend([s(log), sidecar.clone()]);
                let mut inputs = vec![s(log), sidecar];
                inputs.extend(robot.robot.urdf.as_ref().map(|u| s(u)));
                self.stages.push(Stage {
                    id: format!("preprocess_{what}_{i}"),
                    phase: Until::Data,
                    args,
                    inputs,
                    outputs: vec![ds.clone(), ds.replace(".csv", ".json")],
                });
                if what == "train" {
                    lists.0.push(ds);
                } else {
                    lists.1.push(ds);
                }
            }
        }
        Ok(lists)
    }

    /// A joint with the robot's own logs (`import`): `frictl import FORMAT` of its training logs
    /// into one dataset (a run per log) and of its held-out logs into another, with the joint's
    /// name, gear ratio and k_t and the robot's URDF; returns the (train, test) datasets.
    fn import_logs(&mut self) -> anyhow::Result<(Vec<String>, Vec<String>)> {
        let (robot, j) = (self.robot, self.j);
        let imp = j.import.as_ref().context("a joint without an import")?;
        let format = imp.format.context("an import without a format")?;
        let options = imp.option_words().map_err(|(key, value, why)| {
            anyhow::anyhow!("joint {}: import.{key} = {value}: {why}", j.name)
        })?;
        let urdf = match imp.options.get("urdf") {
            Some(_) => None,
            None => robot.robot.urdf.as_ref().map(|u| s(u)),
        };
        let mut lists = (vec![], vec![]);
        for (what, logs) in [("train", &imp.logs), ("test", &imp.test_logs)] {
            if logs.is_empty() {
                continue;
            }
            let ds = self.f(&format!("{what}_ds.csv"));
            let mut args: Vec<String> = ["import", format.name()].map(String::from).into();
            args.extend(options.iter().cloned());
            args.extend([
                "--joint".into(),
                j.name.clone(),
                format!("--gear-ratio={}", j.gear_ratio),
                format!("--kt={}", j.kt_nm_per_a),
            ]);
            args.extend(urdf.iter().flat_map(|u| ["--urdf".to_owned(), u.clone()]));
            args.extend(["--out".into(), ds.clone(), "--".into()]);
            args.extend(logs.iter().map(|l| s(l)));
            format.check_argv(&args).with_context(|| {
                format!(
                    "joint {}: the import ({options:?}) is not a `frictl import {}` command line",
                    j.name,
                    format.name()
                )
            })?;
            let mut inputs: Vec<String> = logs.iter().map(|l| s(l)).collect();
            inputs.extend(urdf.iter().cloned());
            if let Some(toml::Value::String(u)) = imp.options.get("urdf") {
                inputs.push(u.clone());
            }
            self.external_inputs.extend(inputs.iter().cloned());
            self.stages.push(Stage {
                id: format!("import_{what}"),
                phase: Until::Data,
                args,
                inputs,
                outputs: vec![ds.clone(), ds.replace(".csv", ".json")],
            });
            if what == "train" {
                lists.0.push(ds);
            } else {
                lists.1.push(ds);
            }
        }
        Ok(lists)
    }

    /// A joint with labelled datasets (`datasets`, `test_datasets`): no stage; returns them.
    fn given_datasets(&mut self) -> (Vec<String>, Vec<String>) {
        let j = self.j;
        let all = |v: &[PathBuf]| v.iter().map(|p| s(p)).collect::<Vec<_>>();
        for p in j.datasets.iter().chain(&j.test_datasets) {
            self.external_inputs
                .extend([s(p), s(&p.with_extension("json"))]);
        }
        (all(&j.datasets), all(&j.test_datasets))
    }

    /// The CV and SCV fits on the first training dataset; returns their files.
    fn fits(&mut self, train: &[String]) -> anyhow::Result<(String, String)> {
        let (cv, scv) = (self.f("cv.json"), self.f("scv.json"));
        for (m, out) in [(ModelKind::Cv, &cv), (ModelKind::Scv, &scv)] {
            self.stages.push(Stage {
                id: format!("fit_{}", m.name()),
                phase: Until::Fit,
                args: stage::argv(
                    &["fit"],
                    &fit::Args {
                        model: fit::FitModel(m),
                        dataset: PathBuf::from(&train[0]),
                        json: Some(PathBuf::from(out)),
                        ..stage::defaults()?
                    },
                )?,
                inputs: with_sidecars(&train[..1]),
                outputs: vec![out.clone()],
            });
        }
        Ok((cv, scv))
    }

    /// The PINN: a search when `[search] trials` > 0, else one training with `[train]`; returns the
    /// search's arguments (without `--out` and the parallelism, for a driver such as Ray's) and
    /// the model frictiond runs.
    fn model(
        &mut self,
        train: &[String],
        scv: &str,
    ) -> anyhow::Result<(Vec<String>, PlannedModel)> {
        let (robot, j) = (self.robot, self.j);
        let sr = &robot.search;
        // An incremental motor encoder: Δθ latched per chunk, as frictiond latches it at every enable.
        let motor_encoder = match j.motor_encoder {
            frictiond_config::MotorEncoder::Absolute => train::MotorEncoder::Absolute,
            frictiond_config::MotorEncoder::Incremental => train::MotorEncoder::Incremental,
        };
        let mut inputs = with_sidecars(train);
        inputs.push(scv.to_owned());
        let pair = |r: Option<[usize; 2]>| r.map(|r| r.to_vec());
        let search_base = search::Args {
            datasets: train.iter().map(PathBuf::from).collect(),
            scv: PathBuf::from(scv),
            trials: sr.trials,
            seed: robot.robot.seed,
            epochs: sr.epochs,
            features: train::Features(j.features),
            val_frac: sr.val_frac,
            test_frac: sr.test_frac,
            temperature: j.temperature,
            max_epochs_without_improvement: sr.patience,
            batch_range: pair(sr.batch),
            hidden_range: pair(sr.hidden),
            lr_range: sr.lr.map(|r| r.to_vec()),
            history_range: pair(sr.history),
            lambda_range: sr.lambda.map(|r| r.to_vec()),
            dropout_range: sr.dropout.map(|r| r.to_vec()),
            max_rmse_ratio: sr.max_rmse_ratio,
            delta_theta_offset: motor_encoder.latch(DeltaThetaOffset::Run),
            ..stage::defaults()?
        };
        // Completed by its users (the search stage below, the Ray driver) with `--out` and the
        // parallelism.
        let search_args = stage::partial_argv(&["search"], &search_base, &["out"])?;
        let model = if sr.trials > 0 {
            self.search(search_base, inputs)?
        } else {
            self.train_once(train, scv, motor_encoder, inputs)?
        };
        Ok((search_args, model))
    }

    /// The search stage (`[search]`): writes both the best and the picked model; the robot runs
    /// the one the file asks for.
    fn search(&mut self, base: search::Args, inputs: Vec<String>) -> anyhow::Result<PlannedModel> {
        let sr = &self.robot.search;
        let sd = self.f("search");
        let args = stage::argv(
            &["search"],
            &search::Args {
                out: PathBuf::from(&sd),
                resume: true,
                parallel: sr.parallel,
                threads: Some(sr.parallel * sr.threads_per_trial),
                quiet: true,
                ..base
            },
        )?;
        let which = if sr.pick { "pick" } else { "best" };
        let (m, r) = (
            format!("{sd}/{which}.fwt"),
            format!("{sd}/{which}.train.json"),
        );
        self.stages.push(Stage {
            id: "search".into(),
            phase: Until::Search,
            args,
            inputs,
            outputs: vec![m.clone(), r.clone(), format!("{sd}/results.json")],
        });
        Ok(PlannedModel {
            fwt: m,
            report: r,
            search_dir: Some(sd),
        })
    }

    /// One training with the robot file's `[train]` settings.
    fn train_once(
        &mut self,
        train: &[String],
        scv: &str,
        motor_encoder: train::MotorEncoder,
        inputs: Vec<String>,
    ) -> anyhow::Result<PlannedModel> {
        let (robot, j) = (self.robot, self.j);
        let (t, sr) = (&robot.train, &robot.search);
        let (m, r) = (self.f("pinn.fwt"), self.f("pinn.train.json"));
        let args = stage::argv(
            &["train"],
            &train::Args {
                datasets: train.iter().map(PathBuf::from).collect(),
                scv: PathBuf::from(scv),
                out: PathBuf::from(&m),
                report: Some(PathBuf::from(&r)),
                features: train::Features(j.features),
                hidden: t.hidden.clone(),
                history: t.history,
                epochs: t.epochs,
                batch: t.batch,
                lr: t.lr,
                lambda: t.lambda,
                dropout: t.dropout,
                seed: robot.robot.seed,
                threads: Some(sr.threads_per_trial),
                val_frac: sr.val_frac,
                test_frac: sr.test_frac,
                temperature: j.temperature,
                motor_encoder,
                ..stage::defaults()?
            },
        )?;
        self.stages.push(Stage {
            id: "train".into(),
            phase: Until::Search,
            args,
            inputs,
            outputs: vec![m.clone(), r.clone()],
        });
        Ok(PlannedModel {
            fwt: m,
            report: r,
            search_dir: None,
        })
    }

    /// The evaluation of CV, SCV and the PINN on the held-out datasets (none: the split's test
    /// chunks of the training datasets).
    fn evaluate(
        &mut self,
        train: &[String],
        test: &[String],
        [cv, scv]: [&str; 2],
        model: &PlannedModel,
    ) -> anyhow::Result<()> {
        let eval_json = self.f("eval.json");
        let (eval_sets, test_only) = if test.is_empty() {
            (train, true)
        } else {
            (test, false)
        };
        let eval_args = stage::argv(
            &["eval"],
            &eval::Args {
                datasets: eval_sets.iter().map(PathBuf::from).collect(),
                cv: Some(PathBuf::from(cv)),
                scv: Some(PathBuf::from(scv)),
                pinns: vec![PathBuf::from(&model.fwt)],
                train_report: Some(PathBuf::from(&model.report)),
                out: Some(PathBuf::from(self.f("eval"))),
                json: Some(PathBuf::from(&eval_json)),
                test_only,
                ..stage::defaults()?
            },
        )?;
        let mut eval_inputs = with_sidecars(eval_sets);
        eval_inputs.extend([
            cv.to_owned(),
            scv.to_owned(),
            model.fwt.clone(),
            model.report.clone(),
        ]);
        self.stages.push(Stage {
            id: "eval".into(),
            phase: Until::Eval,
            args: eval_args,
            inputs: eval_inputs,
            outputs: vec![eval_json],
        });
        Ok(())
    }

    /// The PINN exported to ONNX.
    fn export(&mut self, fwt: &str) -> anyhow::Result<()> {
        let onnx = self.f(&format!("{}.onnx", self.j.name));
        self.stages.push(Stage {
            id: "export".into(),
            phase: Until::Export,
            args: stage::argv(
                &["export"],
                &export::Args {
                    format: export::Format::Onnx,
                    input: PathBuf::from(fwt),
                    output: PathBuf::from(&onnx),
                    ..stage::defaults()?
                },
            )?,
            inputs: vec![fwt.to_owned()],
            outputs: vec![onnx],
        });
        Ok(())
    }
}

/// Each dataset followed by its JSON sidecar.
fn with_sidecars(v: &[String]) -> Vec<String> {
    v.iter()
        .flat_map(|p| {
            [
                p.clone(),
                Path::new(p).with_extension("json").display().to_string(),
            ]
        })
        .collect()
}

/// `frictl preprocess` of a joint: `base`, then the robot file's `preprocess_args` for the joint,
/// checked by clap here so a bad one is refused when the plan is made, naming the joint.
fn preprocess_argv(j: &JointSection, base: preprocess::Args) -> anyhow::Result<Vec<String>> {
    let mut words = stage::argv(&["preprocess"], &base)?;
    if !j.preprocess_args.is_empty() {
        // The extras go before the positional part (`-- LOG`).
        let at = words.iter().position(|w| w == "--").unwrap_or(words.len());
        words.splice(at..at, j.preprocess_args.iter().cloned());
        stage::roundtrip::<preprocess::Args>(1, &words).with_context(|| {
            format!("joint {}: preprocess_args {:?}", j.name, j.preprocess_args)
        })?;
    }
    Ok(words)
}

/// SHA-256 of a file's content (hex).
fn file_sha256(p: &Path) -> anyhow::Result<String> {
    frictionless_dataset::file_sha256_hex(p).with_context(|| format!("cannot read {}", p.display()))
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

/// The stamp of a stage: its arguments with each input path replaced by its content hash.
fn stamp(out: &Path, st: &Stage) -> anyhow::Result<String> {
    let mut h = Sha256::new();
    let mut hashes = BTreeMap::new();
    for i in &st.inputs {
        hashes.insert(i.clone(), file_sha256(&out.join(i))?);
    }
    for a in &st.args {
        let part = hashes.get(a).map_or(a.as_str(), |x| x.as_str());
        h.update(part.as_bytes());
        h.update([0]);
    }
    for i in &st.inputs {
        h.update(hashes[i].as_bytes());
    }
    Ok(hex(&h.finalize()))
}

/// The stamp file's text: the input stamp ([`stamp`]), then one `SHA256  PATH` line per output as
/// the stage wrote it.
fn stamp_text(out: &Path, st: &Stage, inputs: &str) -> anyhow::Result<String> {
    let mut t = format!("{inputs}\n");
    for o in &st.outputs {
        t += &format!("{}  {o}\n", file_sha256(&out.join(o))?);
    }
    Ok(t)
}

/// Why a stage whose input stamp matches must run again: an output missing, not recorded, or not
/// the file the stage wrote (damaged or edited since). None when every output is as written.
fn outputs_changed(out: &Path, st: &Stage, stamp_lines: &[&str]) -> Option<String> {
    let recorded: BTreeMap<&str, &str> = stamp_lines
        .iter()
        .filter_map(|l| l.split_once("  "))
        .map(|(h, p)| (p, h))
        .collect();
    st.outputs.iter().find_map(|o| {
        let p = out.join(o);
        match recorded.get(o.as_str()) {
            _ if !p.is_file() => Some(format!("{o} is missing")),
            None => Some(format!("{o} has no recorded hash")),
            Some(h) => match frictionless_dataset::file_sha256_hex(&p) {
                Ok(x) if x == *h => None,
                Ok(_) => Some(format!(
                    "{o} is not the file the stage wrote (changed since)"
                )),
                Err(e) => Some(format!("{o} cannot be read ({e})")),
            },
        }
    })
}

/// Name of the lock file in the output directory (its content: the holder's PID).
const LOCK_FILE: &str = ".robot-run.lock";

/// Takes the output directory's lock (an exclusive `flock` on `DIR/.robot-run.lock`, held until the
/// returned file is dropped or the process ends, also by SIGKILL): a second `frictl robot run` on
/// the same directory is refused, naming the holder's PID, before it reads or writes anything there.
fn lock_out(out: &Path) -> anyhow::Result<std::fs::File> {
    use std::io::{Seek, Write};
    use std::os::unix::fs::OpenOptionsExt;
    let path = out.join(LOCK_FILE);
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&path)
        .with_context(|| format!("cannot open the lock file {}", path.display()))?;
    match f.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            let holder = std::fs::read_to_string(&path).unwrap_or_default();
            let holder = holder.trim();
            bail!(
                "{}: another `frictl robot run` (pid {}) is running on this output directory (it \
                 holds {}); wait for it to end or pass another --out",
                out.display(),
                if holder.is_empty() { "unknown" } else { holder },
                path.display()
            );
        }
        Err(std::fs::TryLockError::Error(e)) => {
            return Err(e).with_context(|| format!("cannot lock {}", path.display()));
        }
    }
    f.set_len(0)
        .and_then(|()| f.rewind())
        .and_then(|()| writeln!(f, "{}", std::process::id()))
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(f)
}

/// SIGINT, SIGTERM and SIGHUP (a terminal, Slurm and systemd stop a job with them): the number of the
/// last one received, 0 while none.
fn stop_signal() -> anyhow::Result<Arc<AtomicUsize>> {
    let flag = Arc::new(AtomicUsize::new(0));
    for sig in [
        signal_hook::consts::SIGINT,
        signal_hook::consts::SIGTERM,
        signal_hook::consts::SIGHUP,
    ] {
        signal_hook::flag::register_usize(sig, flag.clone(), sig as usize)
            .context("cannot install the signal handlers")?;
    }
    Ok(flag)
}

/// The error of a run stopped by signal `sig`.
fn stopped(sig: usize, what: &str) -> anyhow::Error {
    let name = nix::sys::signal::Signal::try_from(sig as i32).map_or("a signal", |s| s.as_str());
    anyhow::anyhow!(
        "stopped by {name} {what}; the stage's outputs are not stamped: `frictl robot run` again \
         resumes there"
    )
}

/// Waits for a stage's child; on a stop signal forwards it, waits up to 5 s, then kills, and always
/// reaps the child before returning (no stage outlives `frictl robot run`).
fn wait_child(
    child: &mut std::process::Child,
    stop: &AtomicUsize,
) -> anyhow::Result<Result<std::process::ExitStatus, usize>> {
    let poll = Duration::from_millis(50);
    loop {
        if let Some(st) = child.try_wait()? {
            return Ok(Ok(st));
        }
        let sig = stop.load(Ordering::SeqCst);
        if sig != 0 {
            let pid = nix::unistd::Pid::from_raw(child.id() as i32);
            let forward = nix::sys::signal::Signal::try_from(sig as i32)
                .unwrap_or(nix::sys::signal::Signal::SIGTERM);
            let _ = nix::sys::signal::kill(pid, forward);
            let grace = Instant::now();
            while child.try_wait()?.is_none() {
                if grace.elapsed() > Duration::from_secs(5) {
                    let _ = child.kill();
                    break;
                }
                std::thread::sleep(poll);
            }
            child.wait()?;
            return Ok(Err(sig));
        }
        std::thread::sleep(poll);
    }
}

/// Runs one stage unless its stamp matches: the same inputs, and every output the file it wrote
/// (hashes in the stamp). Returns (seconds, skipped).
fn run_stage(
    exe: &Path,
    out: &Path,
    joint_dir: &str,
    st: &Stage,
    stop: &AtomicUsize,
) -> anyhow::Result<(f64, bool)> {
    let stamps = out.join(joint_dir).join("stamps");
    std::fs::create_dir_all(&stamps)
        .with_context(|| format!("cannot create {}", stamps.display()))?;
    let stamp_path = stamps.join(format!("{}.sha256", st.id));
    for i in &st.inputs {
        if !out.join(i).is_file() {
            bail!("stage {}: input {} does not exist", st.id, i);
        }
    }
    let want = stamp(out, st)?;
    let have = std::fs::read_to_string(&stamp_path).unwrap_or_default();
    let have: Vec<&str> = have.lines().collect();
    if have.first().map(|l| l.trim()) == Some(want.as_str()) {
        match outputs_changed(out, st, &have[1..]) {
            None => {
                eprintln!("     {joint_dir}: {} up to date", st.id);
                return Ok((0.0, true));
            }
            Some(why) => eprintln!(
                "     {joint_dir}: {}: {why}; running the stage again",
                st.id
            ),
        }
    }
    let _ = std::fs::remove_file(&stamp_path);
    let logs = out.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
    let log = logs.join(format!("{}_{}.log", joint_dir.replace('/', "_"), st.id));
    let f = frictionless::output_file::create_log(&log)
        .with_context(|| format!("cannot create {}", log.display()))?;
    eprintln!("     {joint_dir}: {} …", st.id);
    let t0 = Instant::now();
    let sig = stop.load(Ordering::SeqCst);
    if sig != 0 {
        return Err(stopped(sig, &format!("before {joint_dir}: {}", st.id)));
    }
    let mut cmd = Command::new(exe);
    crate::die_with_parent(&mut cmd);
    let mut child = cmd
        .args(&st.args)
        .current_dir(out)
        .stdin(Stdio::null())
        .stdout(f.try_clone()?)
        .stderr(f)
        .spawn()
        .with_context(|| format!("cannot start {}", exe.display()))?;
    let status = match wait_child(&mut child, stop)? {
        Ok(status) => status,
        Err(sig) => {
            return Err(stopped(
                sig,
                &format!(
                    "during {joint_dir}: {} (its frictl, pid {}, was ended and reaped)",
                    st.id,
                    child.id()
                ),
            ));
        }
    };
    let secs = t0.elapsed().as_secs_f64();
    if !status.success() {
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().collect();
        bail!(
            "{joint_dir}: stage {} failed ({status}): frictl {}\n… {}:\n{}",
            st.id,
            st.args.join(" "),
            log.display(),
            lines[lines.len().saturating_sub(20)..].join("\n")
        );
    }
    for o in &st.outputs {
        if !out.join(o).is_file() {
            bail!("{joint_dir}: stage {} wrote no {o}", st.id);
        }
    }
    frictionless::output_file::write(&stamp_path, stamp_text(out, st, &want)?)
        .with_context(|| format!("cannot write {}", stamp_path.display()))?;
    eprintln!("       done in {secs:.1} s");
    Ok((secs, false))
}

/// The data of a joint must be the joint the file names (name, signed gear ratio, k_t).
fn check_data(
    robot_path: &Path,
    out: &Path,
    i: usize,
    j: &JointSection,
    plan: &JointPlan,
) -> anyhow::Result<()> {
    let paths: Vec<PathBuf> = plan.train.iter().map(|p| out.join(p)).collect();
    let src = pipeline::load_sources(&paths)?;
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * a.abs().max(b.abs());
    let r = src.gear_ratio.get();
    let mismatch = |key: &str, given: String, data: String| {
        anyhow::anyhow!(
            "{}: joint[{i}].{key} = {given}, but the data ({}) has {data}",
            robot_path.display(),
            plan.train[0]
        )
    };
    if src.joint != j.name {
        return Err(mismatch(
            "name",
            format!("{:?}", j.name),
            format!("{:?}", src.joint),
        ));
    }
    if !close(r, j.gear_ratio) {
        return Err(mismatch(
            "gear_ratio",
            j.gear_ratio.to_string(),
            r.to_string(),
        ));
    }
    if !close(src.kt_nm_per_a, j.kt_nm_per_a) {
        return Err(mismatch(
            "kt_nm_per_a",
            j.kt_nm_per_a.to_string(),
            src.kt_nm_per_a.to_string(),
        ));
    }
    Ok(())
}

fn read_typed<T: serde::de::DeserializeOwned>(p: &Path) -> anyhow::Result<T> {
    let t = frictionless::regular_file::read_text(p)
        .with_context(|| format!("cannot read {}", p.display()))?;
    serde_json::from_str(&t).with_context(|| format!("{}: not the expected JSON", p.display()))
}

/// The frictiond config of the robot: every joint with its PINN (model paths relative to `out`), its
/// encoder kind, the Δθ offset its training latched (none for an incremental encoder: latched at
/// every enable), and its CV fit as the static model it falls back to while its inputs are out of
/// the training range (`ood = "static"`).
fn daemon_config(robot: &RobotFile, plans: &[JointPlan], out: &Path) -> anyhow::Result<RawConfig> {
    let mut joints = vec![];
    for (index, (j, p)) in robot.joint.iter().zip(plans).enumerate() {
        let report: TrainReport = read_typed(&out.join(&p.model_report))?;
        let offset = report
            .deployed_offset_rad()
            .map_err(|e| anyhow::anyhow!("{}: {e}", p.model_report))?;
        if offset.is_some() && j.motor_encoder == frictiond_config::MotorEncoder::Incremental {
            bail!(
                "{}: joint {} has motor_encoder = \"incremental\", but its model was trained with a fixed Δθ offset; it must be trained latched per chunk",
                p.model_report,
                j.name
            );
        }
        let cv = frictionless_dataset::fit_file::FittedModel::read_cv(&out.join(&p.cv))
            .with_context(|| format!("the static fallback of joint {}", j.name))?;
        joints.push(JointConfig {
            name: j.name.clone(),
            index,
            gear_ratio: j.gear_ratio,
            kt: j.kt_nm_per_a,
            max_curr: j.max_curr_a,
            speed_current_limit: None,
            kfc: j.kfc,
            kp: 0.0,
            ki: 0.0,
            max_output_friction: j.max_output_friction_nm.unwrap_or(f64::INFINITY),
            joint_velocity_threshold_rad_s: 0.0,
            lpf: j.lpf.map(|l| LpfConfig {
                order: l.order,
                cutoff_hz: l.cutoff_hz,
            }),
            friction_model: ModelKind::Pinn,
            kc: Some(cv.kc),
            kv: Some(cv.kv),
            ka: Some(cv.ka),
            ks: None,
            vs: None,
            alpha: None,
            sigma0: None,
            sigma1: None,
            model: Some(PathBuf::from(&p.model)),
            model_for: None,
            warmup: WarmupName::HoldZero,
            delta_theta_offset_motor_rad: offset,
            motor_encoder: j.motor_encoder,
            ood: OodMode::Static,
            ood_margin: default_ood_margin(),
            ood_ramp_ms: default_ood_ramp_ms(),
            alternate: Vec::new(),
        });
    }
    Ok(RawConfig::shm(joints))
}

/// One joint's report entry.
#[derive(serde::Serialize)]
struct JointReport {
    source: String,
    gear_ratio: f64,
    kt_nm_per_a: f64,
    features: &'static str,
    /// Whether the motor temperature is an input.
    temperature: bool,
    model: String,
    onnx: String,
    /// CV and SCV fit RMSE on the training data [Nm] (the fit JSON's `rmse_fitted_nm`).
    fit_rmse_nm: BTreeMap<String, Option<f64>>,
    search: Option<SearchSummary>,
    /// Evaluation RMSE over all samples per model [Nm] (`null`: no value).
    eval_rmse_nm: BTreeMap<String, Option<f64>>,
    /// The evaluation's own JSON.
    eval: String,
    stages: Vec<StageRecord>,
}

#[derive(serde::Serialize)]
struct SearchSummary {
    trials: usize,
    ok: usize,
    failed: usize,
    best_trial: Option<usize>,
    best_val_rmse_nm: Option<f64>,
    best_test_rmse_nm: Option<f64>,
    trial_seconds_total: f64,
}

#[derive(Clone, serde::Serialize)]
struct StageRecord {
    id: String,
    seconds: f64,
    skipped: bool,
}

fn joint_report(
    j: &JointSection,
    p: &JointPlan,
    out: &Path,
    stages: Vec<StageRecord>,
) -> anyhow::Result<JointReport> {
    let mut fit_rmse_nm = BTreeMap::new();
    for (m, f) in [("cv", &p.cv), ("scv", &p.scv)] {
        let v: serde_json::Value = read_typed(&out.join(f))?;
        fit_rmse_nm.insert(
            m.to_owned(),
            v.get("rmse_fitted_nm").and_then(|x| x.as_f64()),
        );
    }
    let search = match &p.search_dir {
        None => None,
        Some(sd) => {
            let rs: Vec<TrialResult> = frictionless_train::search::dedup(read_results(
                &out.join(sd).join("results.jsonl"),
            )?);
            let mut ranked = rs.clone();
            frictionless_train::search::rank(&mut ranked);
            let best = ranked.first().filter(|r| r.status == "ok");
            Some(SearchSummary {
                trials: rs.len(),
                ok: rs.iter().filter(|r| r.status == "ok").count(),
                failed: rs.iter().filter(|r| r.status != "ok").count(),
                best_trial: best.map(|b| b.params.trial),
                best_val_rmse_nm: best.and_then(|b| b.val_rmse_nm),
                best_test_rmse_nm: best.and_then(|b| b.test_rmse_nm),
                trial_seconds_total: rs.iter().map(|r| r.seconds).sum(),
            })
        }
    };
    let eval_path = format!("{}/eval.json", p.dir);
    let ev: EvalReport = read_typed(&out.join(&eval_path))?;
    let eval_rmse_nm = ["none", "cv", "scv", "pinn"]
        .iter()
        .map(|k| ((*k).to_owned(), ev.models.get(*k).and_then(|m| m.rmse_all)))
        .collect();
    Ok(JointReport {
        source: match j.source() {
            DataSource::Preset => format!("preset {}", j.preset.as_deref().unwrap_or("")),
            DataSource::Logs => format!("{} log(s)", j.logs.len()),
            DataSource::Datasets => format!("{} dataset(s)", j.datasets.len()),
            DataSource::Import => match &j.import {
                Some(i) => format!(
                    "{} {} log(s)",
                    i.logs.len(),
                    i.format.map_or("?", |f| f.name())
                ),
                None => String::new(),
            },
        },
        gear_ratio: j.gear_ratio,
        kt_nm_per_a: j.kt_nm_per_a,
        features: j.features.name(),
        temperature: j.temperature,
        model: p.model.clone(),
        onnx: format!("{}/{}.onnx", p.dir, j.name),
        fit_rmse_nm,
        search,
        eval_rmse_nm,
        eval: eval_path,
        stages,
    })
}

fn opt(v: Option<f64>) -> String {
    v.map_or("–".into(), |x| format!("{x:.4}"))
}

fn report_md(robot: &RobotFile, joints: &BTreeMap<String, JointReport>, total_s: f64) -> String {
    // What trained each PINN: the search's trials, or (trials = 0) one `[train]` run.
    let training = if robot.search.trials == 0 {
        let t = &robot.train;
        format!(
            "one training ([train]: hidden {:?}, history {}, {} epoch(s), batch {})",
            t.hidden, t.history, t.epochs, t.batch
        )
    } else {
        format!(
            "search: {} trial(s) × {} epoch(s)",
            robot.search.trials, robot.search.epochs
        )
    };
    let mut md = format!(
        "# {}: friction models\n\nSeed {}; {} joint(s); {training} per joint. Total {:.0} s.\nfrictiond config: `frictiond.toml` (`frictiond --config frictiond.toml --check`).\n\n",
        robot.robot.name,
        robot.robot.seed,
        robot.joint.len(),
        total_s
    );
    md += "| joint | source | r | k_t [Nm/A] | best trial | val RMSE [Nm] | eval RMSE none / CV / SCV / PINN [Nm] |\n|---|---|---|---|---|---|---|\n";
    for j in &robot.joint {
        let Some(r) = joints.get(&j.name) else {
            continue;
        };
        let e = |k: &str| opt(r.eval_rmse_nm.get(k).copied().flatten());
        md += &format!(
            "| {} | {} | {} | {} | {} | {} | {} / {} / {} / {} |\n",
            j.name,
            r.source,
            r.gear_ratio,
            r.kt_nm_per_a,
            r.search
                .as_ref()
                .and_then(|s| s.best_trial)
                .map_or("–".into(), |t| t.to_string()),
            opt(r.search.as_ref().and_then(|s| s.best_val_rmse_nm)),
            e("none"),
            e("cv"),
            e("scv"),
            e("pinn"),
        );
    }
    md += "\n## Stages\n\n| joint | stage | seconds | skipped |\n|---|---|---|---|\n";
    for j in &robot.joint {
        let Some(r) = joints.get(&j.name) else {
            continue;
        };
        for st in &r.stages {
            md += &format!(
                "| {} | {} | {:.1} | {} |\n",
                j.name,
                st.id,
                st.seconds,
                if st.skipped { "yes" } else { "" }
            );
        }
    }
    md
}

/// Runs `frictl robot`.
pub fn run(args: Args, host: &dyn Host) -> anyhow::Result<()> {
    match args.action {
        Action::Plan(a) => {
            let robot = crate::robot::load(&a.robot)?;
            let plans: Vec<JointPlan> = robot
                .joint
                .iter()
                .map(|j| plan_joint(&robot, j))
                .collect::<anyhow::Result<_>>()?;
            let v = serde_json::json!({
                "format": "frictionless-robot-plan-v1",
                "out": s(&a.out),
                "shared_dir": robot.robot.shared_dir.as_ref().map(|d| s(d)),
                "threads_per_trial": robot.search.threads_per_trial,
                "joints": plans,
            });
            println!("{}", serde_json::to_string_pretty(&v)?);
            Ok(())
        }
        Action::Run(a) => run_robot(a, host),
    }
}

fn run_robot(a: RunArgs, host: &dyn Host) -> anyhow::Result<()> {
    let started = Instant::now();
    let robot = crate::robot::load(&a.robot)?;
    for name in &a.joints {
        if !robot.joint.iter().any(|j| &j.name == name) {
            bail!("--joint {name}: not a joint of {}", a.robot.display());
        }
    }
    let out = &a.out;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let _lock = lock_out(out)?;
    let stop = stop_signal()?;
    // Children run in `out`: every path they get is relative to it or absolute.
    let exe = host.frictl()?;
    let until = a.until.unwrap_or(Until::Export);
    let plans: Vec<JointPlan> = robot
        .joint
        .iter()
        .map(|j| plan_joint(&robot, j))
        .collect::<anyhow::Result<_>>()?;
    let mut reports = BTreeMap::new();
    for (i, (j, p)) in robot.joint.iter().zip(&plans).enumerate() {
        if !a.joints.is_empty() && !a.joints.contains(&j.name) {
            continue;
        }
        eprintln!("[{}/{}] {}", i + 1, robot.joint.len(), j.name);
        std::fs::create_dir_all(out.join(&p.dir))
            .with_context(|| format!("cannot create {}", out.join(&p.dir).display()))?;
        let mut records = vec![];
        let mut checked = false;
        for st in p.stages.iter().filter(|st| st.phase <= until) {
            if st.phase > Until::Data && !checked {
                check_data(&a.robot, out, i, j, p)?;
                checked = true;
            }
            let (seconds, skipped) = run_stage(&exe, out, &p.dir, st, &stop)?;
            records.push(StageRecord {
                id: st.id.clone(),
                seconds,
                skipped,
            });
        }
        if until == Until::Data {
            check_data(&a.robot, out, i, j, p)?;
        }
        if until == Until::Export {
            reports.insert(j.name.clone(), joint_report(j, p, out, records)?);
        }
    }
    if until < Until::Export || !a.joints.is_empty() && a.joints.len() < robot.joint.len() {
        eprintln!(
            "frictl robot run: stages done in {:.1} s (no config or report: not every joint ran to the end)",
            started.elapsed().as_secs_f64()
        );
        return Ok(());
    }
    let cfg = daemon_config(&robot, &plans, out)?;
    let cfg_path = out.join("frictiond.toml");
    let text = format!(
        "# Written by `frictl robot run {}`: every joint with its trained PINN (paths relative to this file).\n{}",
        a.robot.display(),
        toml::to_string(&cfg)?
    );
    // The config must load as frictiond loads it (model files, joint names, k_t).
    frictiond_config::parse(&cfg_path, &text).with_context(|| {
        format!(
            "{}: the written config does not validate",
            cfg_path.display()
        )
    })?;
    frictionless::output_file::write(&cfg_path, &text)
        .with_context(|| format!("cannot write {}", cfg_path.display()))?;
    let total = started.elapsed().as_secs_f64();
    let report = serde_json::json!({
        "format": "frictionless-robot-v1",
        "producer": format!("frictl {}", env!("CARGO_PKG_VERSION")),
        "robot": robot.robot.name,
        "seed": robot.robot.seed,
        "config": "frictiond.toml",
        "joints": reports,
        "total_seconds": total,
    });
    frictionless::output_file::write(
        out.join("report.json"),
        serde_json::to_string_pretty(&report)?,
    )
    .context("cannot write report.json")?;
    let md = report_md(&robot, &reports, total);
    frictionless::output_file::write(out.join("report.md"), &md)
        .context("cannot write report.md")?;
    println!("{md}");
    eprintln!(
        "frictl robot run: done in {total:.0} s → {} (frictiond.toml, report.md, report.json)",
        out.display()
    );
    Ok(())
}

//! `frictl import csv|mat … --window-samples N`: the import without holding the log. The reader hands
//! its rows in blocks to `frictionless-ident`'s [`StreamLabeller`] (windows of N grid samples with
//! margins derived from the smoother and filter settings, the rows equal to the whole-log import),
//! whose rows are appended to each joint's dataset as they come. Every output is written through
//! the atomic writer and appears, complete with its sidecar, only at the end.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use frictionless::output_file::AtomicFile;
use frictionless_dataset::{Dataset, LabelSource};
use frictionless_ident::preprocess::{
    Dynamics, JointLabel, PreprocessConfig, RunJoints, SignalsLabel, StatePlan, WholeBody,
};
use frictionless_ident::stream::{StreamLabeller, StreamStats};
use frictionless_logs::{ImportedRun, Role, Unit, csv_log};

use crate::options::CommonOptions;

use crate::check_outputs;
use crate::shared::{Inputs, commit_pair, out_path, per_joint, plausibility};

/// One joint's output being written.
struct Out {
    path: PathBuf,
    file: AtomicFile,
    rows: usize,
    valid: usize,
}

/// The state of a streamed import between blocks.
struct Streamer<'a> {
    common: &'a CommonOptions,
    label: LabelSource,
    dynamics: Dynamics<'a>,
    window: usize,
    joints: Vec<JointLabel>,
    labeller: Option<StreamLabeller<'a>>,
    outs: Vec<Out>,
    state_names: Vec<String>,
    /// Whether the log gives a base orientation, and the frame it names for it.
    base: Option<Option<String>>,
    wrench_frames: Vec<String>,
    /// The declared units (a CSV's), for the plausibility check's suggested fixes.
    units: Option<&'a [(Role, Unit)]>,
    /// Whether the next block is the first of its log: the plausibility check runs on it.
    first_of_log: bool,
    /// The plausibility check's warnings, for every log so far.
    findings: Vec<String>,
}

impl<'a> Streamer<'a> {
    fn block(&mut self, block: ImportedRun) -> anyhow::Result<()> {
        if std::mem::take(&mut self.first_of_log) {
            // Units and rates, on the log's first window (a span or a speed in it is a lower
            // bound of the whole log's): what a wrong declaration leaves in the numbers.
            let gap_s = self.common.gap_s.unwrap_or(0.1);
            let findings = plausibility(std::slice::from_ref(&block), gap_s, self.units)
                .context("checked on the log's first window")?;
            self.findings.extend(
                findings
                    .into_iter()
                    .map(|f| format!("{f} (on the log's first window)")),
            );
        }
        // The whole robot's state, every window (a glitch may be anywhere), once the units and
        // rates passed (a wrong time unit shows as speeds too).
        if let Dynamics::WholeBody(b) = &self.dynamics {
            crate::shared::state_plausibility(std::slice::from_ref(&block), b.robot())?;
        }
        if self.labeller.is_none() {
            for j in &block.joints {
                let mut cfg = PreprocessConfig::for_joint(j);
                cfg.gap_s = self.common.gap_s.unwrap_or(0.1);
                self.common.settings.apply(&mut cfg);
                self.joints.push(JointLabel {
                    joint: j.clone(),
                    label: SignalsLabel {
                        source: self.label,
                        gear_ratio_signed: per_joint(&self.common.gear_ratio, j, "--gear-ratio")?,
                        kt_nm_per_a: per_joint(&self.common.kt, j, "--kt")?,
                    },
                    cfg,
                });
                let path = out_path(&self.common.out, j);
                let file = AtomicFile::create(&path)
                    .with_context(|| format!("cannot write {}", path.display()))?;
                self.outs.push(Out {
                    path,
                    file,
                    rows: 0,
                    valid: 0,
                });
            }
            if let Some(st) = &block.state {
                self.state_names = st.names.clone();
                self.base = st.base_quat_xyzw.as_ref().map(|_| st.base_frame.clone());
                self.wrench_frames = st.wrenches.iter().map(|w| w.frame.clone()).collect();
            }
            self.labeller = Some(StreamLabeller::new(
                &self.joints,
                self.dynamics,
                self.window,
            )?);
        }
        let Some(l) = self.labeller.as_mut() else {
            bail!("no labeller");
        };
        l.push(&RunJoints {
            signals: block.joint_signals().collect(),
            state: block.state.as_ref(),
        })?;
        let rows = l.take_rows();
        self.write(rows)
    }

    fn write(&mut self, rows: Vec<Dataset>) -> anyhow::Result<()> {
        for (o, ds) in self.outs.iter_mut().zip(rows) {
            if ds.is_empty() {
                continue;
            }
            ds.write_csv_part_to(&mut o.file, &o.path, o.rows == 0)?;
            o.rows += ds.len();
            o.valid += ds.valid.iter().filter(|v| **v).count();
        }
        Ok(())
    }
}

/// Runs `frictl import csv` streamed: `spec` and `body` as `run_csv` made them.
pub fn run_csv(
    files: &[PathBuf],
    spec: &csv_log::CsvSpec,
    common: &CommonOptions,
    body: Option<&WholeBody>,
    window: usize,
) -> anyhow::Result<()> {
    let reads = |r: Role| spec.columns.iter().any(|c| c.0 == r);
    let default_label = if reads(Role::TauF) {
        LabelSource::Given
    } else if reads(Role::TauJoint) {
        LabelSource::TorqueSensor
    } else {
        LabelSource::Current
    };
    run_stream(
        files,
        "csv",
        default_label,
        common,
        body,
        Some(&spec.units),
        window,
        |f, stream| csv_log::read_streamed(f, spec, &mut |_, _| {}, stream),
    )
}

/// Runs `frictl import FORMAT` streamed: `read` reads one log, handing its rows to the sink it is
/// given; the label is `--label` or `default_label`; `units` are the declared units (a CSV's),
/// which the plausibility check's fixes name.
#[allow(clippy::too_many_arguments)]
pub fn run_stream(
    files: &[PathBuf],
    format: &str,
    default_label: LabelSource,
    common: &CommonOptions,
    body: Option<&WholeBody>,
    units: Option<&[(Role, Unit)]>,
    window: usize,
    mut read: impl FnMut(
        &Path,
        Option<frictionless_logs::BlockSink<'_>>,
    ) -> Result<ImportedRun, frictionless_logs::LogsError>,
) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    anyhow::ensure!(window > 0, "--window-samples {window}: must be > 0");
    let label: LabelSource = common.label.map_or(default_label, Into::into);
    let dynamics = match (label, body) {
        (LabelSource::Current, Some(b)) => Dynamics::WholeBody(b),
        (LabelSource::Current, None) => bail!(
            "--window-samples with the current label needs the whole-body state: pass --urdf (and \
             for a CSV, --positions TEMPLATE)"
        ),
        _ => Dynamics::None,
    };
    let mut st = Streamer {
        common,
        label,
        dynamics,
        window,
        joints: Vec::new(),
        labeller: None,
        outs: Vec::new(),
        state_names: Vec::new(),
        base: None,
        wrench_frames: Vec::new(),
        units,
        first_of_log: true,
        findings: Vec::new(),
    };
    let mut runs = read_all(&mut st, files, window, &mut read)?;
    frictionless_logs::unique_run_names(&mut runs);
    let Some(labeller) = st.labeller.take() else {
        bail!("no usable rows in {}", files.len());
    };
    let (rest, stats) = labeller.finish()?;
    let mut warnings: Vec<String> = runs.iter().flat_map(|r| r.report.warning_lines()).collect();
    warnings.append(&mut st.findings);
    let (rest, sums): (Vec<Dataset>, Vec<_>) = rest.into_iter().unzip();
    st.write(rest)?;
    let plan = body.map(|b| {
        let names: Vec<String> = st.joints.iter().map(|j| j.joint.clone()).collect();
        let mut p = b.plan(
            &st.state_names,
            &names,
            st.base.as_ref().map(Option::as_deref),
        );
        p.wrenches = st.wrench_frames.clone();
        p
    });
    warnings.extend(plan.iter().flat_map(StatePlan::warnings));
    let inputs = Inputs::hash(files)?;
    let dynamics = match (&plan, body) {
        (Some(p), Some(b)) => format!("{}, streamed", b.describe(p, "settings.import.whole_body")),
        _ => "none (the label does not use inverse dynamics)".into(),
    };
    let gravity_m_s2 = body.map(|b| b.robot().gravity_m_s2());
    let joint_names: Vec<String> = st.joints.iter().map(|j| j.joint.clone()).collect();
    for ((jl, o), sum) in st.joints.iter().zip(st.outs).zip(sums) {
        check_outputs(&inputs.paths(), &[&o.path, &o.path.with_extension("json")])?;
        anyhow::ensure!(
            o.valid > 0,
            "{}: 0 valid samples of {}; check the units and --gap-s",
            jl.joint,
            o.rows
        );
        let settings = serde_json::json!({
            "pipeline": jl.cfg,
            "import": {
                "format": format,
                "label": label,
                "joints_of_this_pass": joint_names,
                "derivations": sum.derivations,
                "whole_body": plan,
                "gravity_m_s2": gravity_m_s2,
                "stream": stream_json(&stats),
                "dropped_single_sample_chunks": sum.dropped_single_sample_chunks,
                "runs": inputs.reports(&runs),
                "warnings": warnings,
            }
        });
        let side = inputs.sidecar(
            &runs,
            jl,
            &sum,
            &Dataset::default(),
            o.rows,
            o.valid,
            dynamics.clone(),
            settings,
        );
        commit_pair(o.file, &o.path, &side)?;
        eprintln!(
            "frictl import {format}: {}: {} samples ({} valid), streamed in windows of {} (+{} / +{} margin) -> {}",
            jl.joint,
            o.rows,
            o.valid,
            stats.window,
            stats.lead,
            stats.trail,
            o.path.display()
        );
        if let Some(line) = jl.cfg.limits.dropped_rows_line(&sum.dropped, o.rows) {
            eprintln!("  {}: {line}", jl.joint);
        }
    }
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    eprintln!(
        "frictl import {format}: {} runs streamed, at most {} grid and {} raw samples held, in {:.2} s",
        runs.len(),
        stats.max_grid_samples,
        stats.max_raw_samples,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Reads every log of `files` through `st`, `window` rows a block; the runs as read.
fn read_all(
    st: &mut Streamer<'_>,
    files: &[PathBuf],
    window: usize,
    read: &mut impl FnMut(
        &Path,
        Option<frictionless_logs::BlockSink<'_>>,
    ) -> Result<ImportedRun, frictionless_logs::LogsError>,
) -> anyhow::Result<Vec<ImportedRun>> {
    let mut runs = Vec::new();
    for f in files {
        st.first_of_log = true;
        let mut failed: Option<anyhow::Error> = None;
        let mut sink = |block: ImportedRun| {
            st.block(block).map_err(|e| {
                let msg = format!("{e:#}");
                failed = Some(e);
                msg
            })
        };
        let stream = frictionless_logs::BlockSink {
            block_rows: window,
            sink: &mut sink,
        };
        let run = read(f, Some(stream));
        if let Some(e) = failed {
            return Err(e.context(format!("labelling {}", f.display())));
        }
        let run = run?;
        if let Some(l) = st.labeller.as_mut() {
            l.end_run()?;
        }
        runs.push(run);
    }
    Ok(runs)
}

fn stream_json(s: &StreamStats) -> serde_json::Value {
    serde_json::json!({
        "window_samples": s.window,
        "lead_margin_samples": s.lead,
        "trail_margin_samples": s.trail,
        "max_grid_samples_held": s.max_grid_samples,
        "max_raw_samples_held": s.max_raw_samples,
        "steps": s.steps,
    })
}

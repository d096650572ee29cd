//! What the whole-log and the streamed import share, below both: the output path per joint, the
//! per-joint values of `R` / `NAME=R` options, the units, rates and
//! whole-state plausibility checks, the inputs' hashes and sidecar, and committing a dataset with
//! its sidecar.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use frictionless_dataset::{ColumnDocOwned, Dataset, DatasetSidecar, RunInfo};
use frictionless_ident::preprocess::{JointLabel, SignalsSummary};
use frictionless_logs::{ImportedRun, Role};
use sha2::Digest;

/// `{joint}` in the output path, replaced for one joint.
pub(crate) const JOINT: &str = "{joint}";

/// `out` with [`JOINT`] replaced by `joint`.
pub(crate) fn out_path(out: &Path, joint: &str) -> PathBuf {
    PathBuf::from(out.to_string_lossy().replace(JOINT, joint))
}

/// Every value of `R` / `NAME=R` options, parsed: (the option's text, the number).
pub(crate) fn per_joint_values<'a>(
    values: &'a [String],
    flag: &str,
) -> anyhow::Result<Vec<(&'a str, f64)>> {
    values
        .iter()
        .map(|v| {
            let x = v.split_once('=').map_or(v.as_str(), |(_, x)| x);
            let n: f64 = x
                .trim()
                .parse()
                .with_context(|| format!("{flag} {v:?}: {x:?} is not a number"))?;
            Ok((v.as_str(), n))
        })
        .collect()
}

/// A per-joint value of `R` / `NAME=R` options: the joint's own, else the one for all.
pub(crate) fn per_joint(values: &[String], joint: &str, flag: &str) -> anyhow::Result<Option<f64>> {
    let mut all = None;
    let mut mine = None;
    for (v, x) in per_joint_values(values, flag)? {
        match v.split_once('=').map(|(n, _)| n.trim()) {
            Some(n) if n == joint => mine = Some(x),
            Some(_) => {}
            None => all = Some(x),
        }
    }
    Ok(mine.or(all))
}

/// The units and rates check ([`frictionless_logs::plausibility`]) of `runs`: an error with every
/// refusal, else the warnings.
pub(crate) fn plausibility(
    runs: &[ImportedRun],
    gap_s: f64,
    units: Option<&[(Role, frictionless_logs::Unit)]>,
) -> anyhow::Result<Vec<String>> {
    let findings = frictionless_logs::plausibility::check(runs, gap_s, units);
    let refused: Vec<&str> = findings
        .iter()
        .filter(|f| f.refuse)
        .map(|f| f.message.as_str())
        .collect();
    if !refused.is_empty() {
        bail!("{}", refused.join("\n"));
    }
    Ok(findings.into_iter().map(|f| f.message).collect())
}

/// Margin outside a joint's URDF limits still taken as a logged position, as a fraction of the
/// limits' span (at least [`LIMIT_MARGIN`]): encoder offsets, limits drawn tight, a simulated leg
/// that does not stop at them.
const LIMIT_MARGIN_OF_SPAN: f64 = 0.5;
/// The smallest such margin \[rad or m\].
const LIMIT_MARGIN: f64 = 0.1;
/// A position step faster than this \[rad/s or m/s\] between two samples is a glitch (≈ 1000 rpm
/// at the joint; the labelled joint's own check warns above 30 rad/s).
const MAX_STATE_SPEED: f64 = 100.0;

/// The whole robot's state checked like the labelled joint, before labelling: every logged joint's
/// position inside its URDF limits (with a margin, [`LIMIT_MARGIN_OF_SPAN`]) and without a step faster than
/// [`MAX_STATE_SPEED`]. The error names the run, the joint (its column) and the sample, and tells a
/// unit mistake (most samples outside the limits: degrees for rad) from a glitch (a few).
pub(crate) fn state_plausibility(
    runs: &[ImportedRun],
    robot: &frictionless_dynamics::Robot,
) -> anyhow::Result<()> {
    for r in runs {
        let Some(st) = &r.state else { continue };
        let t = &r.signals.time_s;
        if let Some(qs) = &st.base_quat_xyzw
            && let Some(k) = (0..qs[0].len()).find(|&k| {
                let n2: f64 = qs.iter().map(|c| c[k] * c[k]).sum();
                !(0.25..=4.0).contains(&n2)
            })
        {
            let q: Vec<f64> = qs.iter().map(|c| c[k]).collect();
            bail!(
                "{}: the base orientation quaternion [x, y, z, w] = {q:?} at t = {:.3} s is not a \
                 rotation (norm {:.3}, a unit quaternion has 1): check the orientation columns \
                 and their order x, y, z, w",
                r.report.source,
                t.get(k).copied().unwrap_or(f64::NAN),
                q.iter().map(|v| v * v).sum::<f64>().sqrt()
            );
        }
        for (name, q) in st.names.iter().zip(&st.q) {
            let Ok(j) = robot.joint_index(name) else {
                continue;
            };
            let joint = &robot.joints[j];
            let margin = (LIMIT_MARGIN_OF_SPAN * (joint.upper - joint.lower)).max(LIMIT_MARGIN);
            let (lo, hi) = (joint.lower - margin, joint.upper + margin);
            let outside: Vec<usize> = (0..q.len())
                .filter(|&k| !(lo..=hi).contains(&q[k]))
                .collect();
            if let Some(&k) = outside.first() {
                let at = t.get(k).copied().unwrap_or(f64::NAN);
                if outside.len() * 2 > q.len() {
                    bail!(
                        "{}: joint `{name}` (whole-body position column): {} of {} samples outside \
                         its URDF limits [{:.3}, {:.3}] and their margin (first {} at t = {at:.3} \
                         s): positions are \
                         in rad; if the log is in degrees, declare the unit (e.g. --unit s=deg)",
                        r.report.source,
                        outside.len(),
                        q.len(),
                        joint.lower,
                        joint.upper,
                        q[k]
                    );
                }
                bail!(
                    "{}: joint `{name}` (whole-body position column): {} sample(s) outside its URDF \
                     limits [{:.3}, {:.3}] and their margin, the first {} at t = {at:.3} s: a \
                     glitch in the log \
                     (remove or repair those rows)",
                    r.report.source,
                    outside.len(),
                    joint.lower,
                    joint.upper,
                    q[k]
                );
            }
            if let Some(k) = (1..q.len().min(t.len())).find(|&k| {
                let dt = t[k] - t[k - 1];
                dt > 0.0 && ((q[k] - q[k - 1]) / dt).abs() > MAX_STATE_SPEED
            }) {
                bail!(
                    "{}: joint `{name}` (whole-body position column) jumps from {} to {} between \
                     t = {:.4} s and {:.4} s (faster than {MAX_STATE_SPEED} rad/s): a glitch in the \
                     log (remove or repair those rows)",
                    r.report.source,
                    q[k - 1],
                    q[k],
                    t[k - 1],
                    t[k]
                );
            }
        }
    }
    Ok(())
}

/// The logs of one import and their SHA-256, as each dataset's sidecar records them.
pub(crate) struct Inputs<'a> {
    files: &'a [PathBuf],
    hashes: Vec<String>,
}

impl<'a> Inputs<'a> {
    /// Hashes every file.
    pub(crate) fn hash(files: &'a [PathBuf]) -> anyhow::Result<Self> {
        let mut hashes = Vec::with_capacity(files.len());
        for f in files {
            hashes.push(
                frictionless_dataset::file_sha256_hex(f)
                    .with_context(|| format!("cannot read {}", f.display()))?,
            );
        }
        Ok(Self { files, hashes })
    }

    /// The files, for [`crate::check_outputs`].
    pub(crate) fn paths(&self) -> Vec<&Path> {
        self.files.iter().map(PathBuf::as_path).collect()
    }

    /// Each run's name, file hash and reader's report.
    pub(crate) fn reports(&self, runs: &[ImportedRun]) -> Vec<serde_json::Value> {
        runs.iter()
            .zip(&self.hashes)
            .map(|(r, h)| serde_json::json!({ "run": r.name, "sha256": h, "report": r.report }))
            .collect()
    }

    /// A dataset's sidecar for `jl`'s rows (`samples`, `valid` of them, with the columns of
    /// `columns_of`) labelled from these logs' `runs`: `settings` as given, the rest from the
    /// label and its summary `sum`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn sidecar(
        &self,
        runs: &[ImportedRun],
        jl: &JointLabel,
        sum: &SignalsSummary,
        columns_of: &Dataset,
        samples: usize,
        valid: usize,
        dynamics: String,
        settings: serde_json::Value,
    ) -> DatasetSidecar {
        DatasetSidecar {
            format: "frictionless-dataset-v1".into(),
            producer: format!("frictl {}", env!("CARGO_PKG_VERSION")),
            input_log: self
                .files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            // One file's hash, or the hash of the files' hashes.
            input_sha256: if self.hashes.len() == 1 {
                self.hashes[0].clone()
            } else {
                format!(
                    "{:x}",
                    sha2::Sha256::digest(self.hashes.join("\n").as_bytes())
                )
            },
            joint: jl.joint.clone(),
            gear_ratio_signed: jl.label.gear_ratio_signed.unwrap_or(1.0),
            kt_nm_per_a: jl.label.kt_nm_per_a.unwrap_or(1.0),
            fs_hz: jl.cfg.fs_hz,
            settings,
            dynamics,
            delta_theta_offset_motor_rad: sum
                .delta_theta_offsets_motor_rad
                .first()
                .copied()
                .filter(|v| v.is_finite())
                .unwrap_or(0.0),
            samples,
            valid_samples: valid,
            chunks: sum.run_chunks.iter().map(Vec::len).sum(),
            short_chunks: sum.short_chunks,
            dropped_rows: sum.dropped,
            columns: columns_of
                .columns()
                .iter()
                .map(ColumnDocOwned::from)
                .collect(),
            label: jl.label.source,
            runs: runs
                .iter()
                .zip(&sum.run_chunks)
                .map(|(r, c)| RunInfo {
                    name: r.name.clone(),
                    source: r.report.source.clone(),
                    chunks: c.clone(),
                })
                .collect(),
            absent_columns: sum.absent_columns.iter().map(|s| s.to_string()).collect(),
        }
    }
}

/// Writes `side` beside the dataset written to `csv` and replaces the previous pair at once (the
/// sidecar last, through [`frictionless::output_file::commit_with_marker`]).
pub(crate) fn commit_pair(
    csv: frictionless::output_file::AtomicFile,
    out: &Path,
    side: &DatasetSidecar,
) -> anyhow::Result<()> {
    let side_path = out.with_extension("json");
    let mut side_out = frictionless::output_file::AtomicFile::create(&side_path)
        .with_context(|| format!("cannot write {}", side_path.display()))?;
    side_out
        .write_all(serde_json::to_string_pretty(side)?.as_bytes())
        .with_context(|| format!("cannot write {}", side_path.display()))?;
    frictionless::output_file::commit_with_marker(vec![csv], side_out)
        .with_context(|| format!("cannot write {} and {}", out.display(), side_path.display()))
}

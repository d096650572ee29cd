//! `frictl eval` — RMSE of none / CV / SCV / LuGre / PINN models on held-out datasets, a printed table, a JSON
//! report and PNG figures; with `--drift`, the drift monitor on a new log (`frictionless_eval::drift`). See
//! `frictionless_eval` for the method, the rows evaluated and the JSON schema.

use std::collections::BTreeSet;
use std::path::PathBuf;

use anyhow::Context;
use frictionless::features::WarmupPolicy;
use frictionless_dataset::bands::ResidualProfile;
use frictionless_dataset::{Dataset, DatasetSidecar, MotionRange, RunInfo, dataset_runs};
use frictionless_eval::drift::{self, Coverage, DriftOptions, DriftReport};
use frictionless_eval::{self as eval, DatasetEval, EvalOptions, ModelSpec, TrainingRange, plot};

pub use frictl_cli::eval::*;

fn pinn_names(paths: &[PathBuf]) -> Vec<String> {
    if paths.len() == 1 {
        return vec!["pinn".into()];
    }
    let mut out: Vec<String> = Vec::new();
    for (i, p) in paths.iter().enumerate() {
        let stem = p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| i.to_string());
        let mut name = format!("pinn:{stem}");
        if out.contains(&name) {
            name = format!("pinn:{stem}#{i}");
        }
        out.push(name);
    }
    out
}

/// Runs `frictl eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    if let Some(json) = &args.json {
        let data: Vec<&PathBuf> = args.datasets.iter().chain(&args.test_datasets).collect();
        let sidecars: Vec<PathBuf> = data.iter().map(|d| d.with_extension("json")).collect();
        let reports: Vec<PathBuf> = args
            .pinns
            .iter()
            .map(|p| frictionless_train::pipeline::default_report_path(p))
            .collect();
        let mut inputs: Vec<&std::path::Path> = data.iter().map(|p| p.as_path()).collect();
        inputs.extend(sidecars.iter().map(PathBuf::as_path));
        inputs.extend(args.pinns.iter().map(PathBuf::as_path));
        inputs.extend(reports.iter().map(PathBuf::as_path));
        inputs.extend(
            [&args.cv, &args.scv, &args.lugre, &args.train_report]
                .into_iter()
                .flatten()
                .map(PathBuf::as_path),
        );
        super::check_outputs(&inputs, &[json])?;
    }
    let opts = EvalOptions {
        v_sliding_rad_s: args.v_sliding,
        warmup: match args.warmup {
            Warmup::HoldZero => WarmupPolicy::HoldZero,
            Warmup::ZeroPad => WarmupPolicy::ZeroPad,
        },
        delta_theta_offset: args.delta_theta_offset,
    };
    let mut models = vec![ModelSpec::none()];
    if let Some(p) = &args.cv {
        models.push(ModelSpec::static_model("cv", eval::load_static_model(p)?));
    }
    if let Some(p) = &args.scv {
        models.push(ModelSpec::static_model("scv", eval::load_static_model(p)?));
    }
    if let Some(p) = &args.lugre {
        models.push(ModelSpec::static_model(
            "lugre",
            eval::load_static_model(p)?,
        ));
    }
    let mut pinn_files = Vec::new();
    for (p, name) in args.pinns.iter().zip(pinn_names(&args.pinns)) {
        let f = frictionless::weights::read_file(p)?;
        models.push(
            ModelSpec::pinn(&name, &f, opts.warmup)
                .with_context(|| format!("PINN {}", p.display()))?,
        );
        pinn_files.push((p.clone(), f));
    }
    eval::runs::check_band_edges(&args.band_edges)?;
    let drift_opts = args.drift.then(|| args.drift_options()).transpose()?;
    let all_paths: Vec<PathBuf> = args
        .datasets
        .iter()
        .chain(&args.test_datasets)
        .cloned()
        .collect();
    let test_chunks: Option<Vec<BTreeSet<u32>>> = if args.test_only {
        let r = args
            .train_report
            .as_ref()
            .context("--test-only needs --train-report")?;
        Some(eval::test_chunks_from_report(r, &all_paths)?)
    } else {
        None
    };

    let mut loaded = Vec::new();
    for p in &all_paths {
        let ds = Dataset::read_csv(p)?;
        let side: Option<DatasetSidecar> =
            frictionless::regular_file::read_text(&p.with_extension("json"))
                .ok()
                .and_then(|t| serde_json::from_str(&t).ok());
        let joint = side.as_ref().map(|s| s.joint.clone()).unwrap_or_default();
        // A PINN whose inputs read a column this dataset lacks is refused by name (a torque-sensed
        // dataset has no motor angle: fine for joint-vel, not for delta-theta-joint-vel).
        for (fp, f) in &pinn_files {
            if let Some(w) = check_pinn_on_dataset(fp, f, p, &ds, side.as_ref())? {
                eprintln!("frictl eval: warning: {w}");
            }
        }
        let runs = dataset_runs(p, side.as_ref(), &ds);
        loaded.push((p.clone(), ds, joint, runs));
    }

    // Held-out runs: the named runs and every run of a --test-dataset; the rest are training runs.
    let holding_out = !args.test_runs.is_empty() || !args.test_datasets.is_empty();
    let mut held: Vec<Vec<RunInfo>> = Vec::new();
    let mut train_range = MotionRange::default();
    for (i, (_, ds, _, runs)) in loaded.iter().enumerate() {
        let whole = i >= args.datasets.len();
        let (h, t): (Vec<RunInfo>, Vec<RunInfo>) = runs
            .iter()
            .cloned()
            .partition(|r| !holding_out || whole || args.test_runs.contains(&r.name));
        for r in &t {
            train_range.merge(&MotionRange::of_chunks(ds, &r.chunks));
        }
        held.push(h);
    }
    for name in &args.test_runs {
        if !held.iter().flatten().any(|r| &r.name == name) {
            let known: Vec<&str> = loaded
                .iter()
                .flat_map(|l| l.3.iter().map(|r| r.name.as_str()))
                .collect();
            anyhow::bail!(
                "--test-run {name}: no dataset has a run of that name (runs: {})",
                known.join(", ")
            );
        }
    }
    let training_range = if holding_out && train_range.rows > 0 {
        Some(TrainingRange {
            source: "datasets".into(),
            range: train_range,
        })
    } else if let Some(r) = &args.train_report {
        let text = frictionless::regular_file::read_text(r)
            .with_context(|| format!("cannot read {}", r.display()))?;
        let v: serde_json::Value =
            serde_json::from_str(&text).with_context(|| format!("{} is not JSON", r.display()))?;
        match v.get("training_range").filter(|x| !x.is_null()) {
            Some(x) => Some(TrainingRange {
                source: "train_report".into(),
                range: serde_json::from_value(x.clone()).with_context(|| {
                    format!("{}: key `training_range` is not a range", r.display())
                })?,
            }),
            None => None,
        }
    } else {
        None
    };

    let mut evals = Vec::new();
    let mut parts = Vec::new();
    let mut evaluated_loaded = Vec::new();
    for (i, (p, ds, joint, _)) in loaded.iter().enumerate() {
        if held[i].is_empty() {
            continue;
        }
        let held_chunks: BTreeSet<u32> = held[i].iter().flat_map(|r| r.chunks.clone()).collect();
        let filter: Option<BTreeSet<u32>> = match (&test_chunks, holding_out) {
            (Some(t), true) => Some(t[i].intersection(&held_chunks).copied().collect()),
            (Some(t), false) => Some(t[i].clone()),
            (None, true) => Some(held_chunks),
            (None, false) => None,
        };
        let ev = eval::evaluate(
            &p.display().to_string(),
            ds,
            &models,
            filter.as_ref(),
            &opts,
        )?;
        let extrap = eval::runs::extrapolated_mask(ds, training_range.as_ref().map(|t| &t.range));
        parts.push((held[i].clone(), extrap));
        evals.push((ev, ds, joint.clone()));
        evaluated_loaded.push(p.clone());
    }
    let scored: usize = evals
        .iter()
        .map(|(ev, _, _)| ev.mask.iter().filter(|m| **m).count())
        .sum();
    if scored == 0 {
        let per: Vec<String> = loaded
            .iter()
            .map(|(p, ds, _, _)| {
                format!(
                    "{}: {} rows, {} valid",
                    p.display(),
                    ds.len(),
                    ds.valid.iter().filter(|v| **v).count()
                )
            })
            .collect();
        anyhow::bail!(
            "0 rows scored, nothing evaluated ({}); a row is scored when it is valid, in a scored run or chunk, every PINN's history is ready and every output is finite",
            per.join("; ")
        );
    }
    let mut report = eval::build_report(&models, &evals, &opts, args.test_only);
    eval::add_breakdown(
        &mut report,
        &models,
        &evals,
        &parts,
        &args.band_edges,
        training_range.clone(),
        opts.v_sliding_rad_s,
    );
    print!("{}", eval::format_table(&report));
    let drift_report = match &drift_opts {
        Some(o) => {
            let d = drift_monitor(&args, o, &models, &pinn_files, &evals, &opts)?;
            print!("{}", drift::format_drift(&d));
            Some(d)
        }
        None => None,
    };
    if let Some(p) = &args.json {
        let mut v = serde_json::to_value(&report)?;
        if let (Some(d), Some(m)) = (&drift_report, v.as_object_mut()) {
            m.insert("drift".into(), serde_json::to_value(d)?);
        }
        frictionless::output_file::write(p, serde_json::to_string_pretty(&v)?)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some(d) = drift_report.as_ref().filter(|d| d.verdict == "unchecked") {
        let why: Vec<String> = d
            .models
            .iter()
            .filter(|m| m.verdict == "unchecked")
            .flat_map(|m| m.reasons.iter().map(move |r| format!("{}: {r}", m.model)))
            .collect();
        anyhow::bail!(
            "--drift: nothing was checked, no verdict ({}); lower --drift-min-samples or score more rows",
            why.join("; ")
        );
    }

    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        if plot::init_font().is_none() {
            eprintln!(
                "frictl eval: no TrueType font found (set FRICTL_FONT=path/to/font.ttf); figures are drawn without text"
            );
        }
        let mut written = Vec::new();
        let range = training_range.as_ref().map(|t| &t.range);
        for (((ev, ds, _), p), (_, extrap)) in evals.iter().zip(&evaluated_loaded).zip(&parts) {
            let stem = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "dataset".into());
            let f = dir.join(format!("{stem}_friction_vs_velocity.png"));
            plot::friction_vs_velocity(&f, ds, ev, &models, range)?;
            written.push(f);
            if let Some(chunk) = plot::pick_chunk(ds, ev, opts.v_sliding_rad_s, args.plot_chunk) {
                let f = dir.join(format!("{stem}_timeseries.png"));
                plot::timeseries(&f, ds, ev, &models, chunk, extrap)?;
                written.push(f);
                // Δθ needs a motor encoder: a dataset without one (NaN column) has no hysteresis.
                if ds.delta_theta_motor_rad[chunk.0..chunk.1]
                    .iter()
                    .any(|v| v.is_finite())
                {
                    let f = dir.join(format!("{stem}_hysteresis.png"));
                    plot::hysteresis(&f, ds, chunk)?;
                    written.push(f);
                } else {
                    eprintln!(
                        "frictl eval: {}: no Δθ (no motor encoder): hysteresis figure skipped",
                        p.display()
                    );
                }
            }
        }
        for m in drift_report.iter().flat_map(|d| &d.models) {
            let name: String = m
                .model
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                .collect();
            let f = dir.join(format!("drift_{name}.png"));
            plot::drift_bands(&f, m)?;
            written.push(f);
        }
        if let Some(r) = &args.train_report {
            let text = frictionless::regular_file::read_text(r)
                .with_context(|| format!("cannot read {}", r.display()))?;
            let v: serde_json::Value = serde_json::from_str(&text)
                .with_context(|| format!("{} is not JSON", r.display()))?;
            let f = dir.join("training_curves.png");
            match plot::training_curves(&f, &v) {
                Ok(()) => written.push(f),
                Err(e) => eprintln!("frictl eval: warning: {e}"),
            }
        }
        for f in &written {
            eprintln!("frictl eval: wrote {}", f.display());
        }
    }
    eprintln!(
        "frictl eval: {} model(s) on {} dataset(s) in {:.2} s",
        models.len(),
        evals.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// Refuses a dataset the PINN `file` (from `model_path`) cannot be run on: a column its inputs read
/// is absent from the dataset (sidecar's `absent_columns`), or the dataset's sidecar records another
/// gear ratio (Δθ would be wrong). Returns a warning when the joint names differ. The one check of
/// `frictl eval` and `frictl convert --dataset`.
pub fn check_pinn_on_dataset(
    model_path: &std::path::Path,
    file: &frictionless::weights::ModelFile,
    ds_path: &std::path::Path,
    ds: &Dataset,
    side: Option<&DatasetSidecar>,
) -> anyhow::Result<Option<String>> {
    let absent = side.map_or(&[][..], |s| &s.absent_columns[..]);
    ds.check_inputs(&file.meta.features, absent)
        .with_context(|| {
            format!(
                "PINN {} on dataset {}",
                model_path.display(),
                ds_path.display()
            )
        })?;
    let Some(s) = side else { return Ok(None) };
    let r = file.meta.gear_ratio.get();
    anyhow::ensure!(
        (r - s.gear_ratio_signed).abs() <= 1e-9 * r.abs(),
        "PINN {} was trained with gear ratio {r} but dataset {} has gear_ratio_signed = {} (Δθ would be wrong)",
        model_path.display(),
        ds_path.display(),
        s.gear_ratio_signed
    );
    Ok(
        (!file.meta.joint_name.is_empty()
            && !s.joint.is_empty()
            && file.meta.joint_name != s.joint)
            .then(|| {
                format!(
                    "PINN {} is for joint {:?}, dataset {} is {:?}",
                    model_path.display(),
                    file.meta.joint_name,
                    ds_path.display(),
                    s.joint
                )
            }),
    )
}

/// `--drift`: every model but `none` on the scored rows against its reference (see
/// `frictionless_eval::drift` for the reference order and the rule).
fn drift_monitor(
    args: &Args,
    o: &DriftOptions,
    models: &[ModelSpec],
    pinn_files: &[(PathBuf, frictionless::weights::ModelFile)],
    evals: &[(DatasetEval, &Dataset, String)],
    opts: &EvalOptions,
) -> anyhow::Result<DriftReport> {
    // The reference datasets, scored like the new log (every valid row whose history is ready).
    let mut refs = Vec::new();
    for p in &args.references {
        let ds = Dataset::read_csv(p)?;
        let side: Option<DatasetSidecar> =
            frictionless::regular_file::read_text(&p.with_extension("json"))
                .ok()
                .and_then(|t| serde_json::from_str(&t).ok());
        let absent = side.as_ref().map_or(&[][..], |s| &s.absent_columns[..]);
        for (fp, f) in pinn_files {
            ds.check_inputs(&f.meta.features, absent)
                .with_context(|| format!("PINN {} on reference {}", fp.display(), p.display()))?;
        }
        let ev = eval::evaluate(&p.display().to_string(), &ds, models, None, opts)?;
        refs.push((ev, ds));
    }
    let ref_pairs: Vec<(&DatasetEval, &Dataset)> = refs.iter().map(|(e, d)| (e, d)).collect();
    let new_pairs: Vec<(&DatasetEval, &Dataset)> = evals.iter().map(|(e, d, _)| (e, *d)).collect();
    let train_report: Option<serde_json::Value> = match &args.train_report {
        Some(r) => Some(
            serde_json::from_str(
                &frictionless::regular_file::read_text(r)
                    .with_context(|| format!("cannot read {}", r.display()))?,
            )
            .with_context(|| format!("{} is not JSON", r.display()))?,
        ),
        None => None,
    };
    let first_pinn = models.len() - pinn_files.len();
    let mut out = Vec::new();
    for (i, m) in models.iter().enumerate().skip(1) {
        let new = ResidualProfile::from_rows(
            drift::residual_rows(&new_pairs, i),
            &args.band_edges,
            o.temperature_bin_c,
        );
        let file = i.checked_sub(first_pinn).map(|j| &pinn_files[j].1);
        let reference = if !ref_pairs.is_empty() {
            Some(drift::Reference {
                source: "reference_datasets".into(),
                profile: ResidualProfile::from_rows(
                    drift::residual_rows(&ref_pairs, i),
                    &args.band_edges,
                    o.temperature_bin_c,
                ),
            })
        } else {
            let from_report = train_report
                .as_ref()
                .filter(|_| file.is_some() && pinn_files.len() == 1)
                .and_then(|v| {
                    drift::train_report_reference(v, &args.band_edges, o.temperature_bin_c)
                });
            from_report.or_else(|| file.and_then(drift::fwt_reference))
        };
        let mut coverage: Option<Coverage> = None;
        for (ev, ds) in &new_pairs {
            let Some(mask) =
                drift::out_of_range_mask(ds, &m.model, opts.delta_theta_offset, o.range_margin)
            else {
                continue;
            };
            let c = coverage.get_or_insert(Coverage {
                rows: 0,
                out_of_range: 0,
                out_of_range_share: 0.0,
                margin: o.range_margin,
            });
            for (k, &out) in mask.iter().enumerate() {
                if ev.mask[k] {
                    c.rows += 1;
                    c.out_of_range += usize::from(out);
                }
            }
        }
        if let Some(c) = &mut coverage {
            c.out_of_range_share = c.out_of_range as f64 / c.rows.max(1) as f64;
        }
        out.push(drift::model_drift(&m.name, new, reference, coverage, o));
    }
    Ok(drift::report(out, o))
}

//! The demo's on-policy rounds (`--onpolicy-rounds`): closed-loop runs with the current PINNs around
//! their minimum K_p, labelled, added to each joint's datasets, and training continued from them; and
//! their table in `report.md`.

use super::*;

/// `report.json` `onpolicy_rounds[]`.
#[derive(serde::Serialize)]
pub(super) struct RoundEntry {
    /// 0 = the PINN trained on the open-loop protocol only.
    round: u32,
    /// Joint name → this round's PINN.
    joints: BTreeMap<String, RoundJoint>,
}

/// `report.json` `onpolicy_rounds[].joints.JOINT`.
#[derive(serde::Serialize)]
pub(super) struct RoundJoint {
    /// The PINN of this round.
    model: String,
    /// Its minimum K_p (the PINN-only search of the round; the last round's from the experiments).
    min_kp: Option<MinKp>,
    /// RMSE of τ̂_F/kfc against the true friction during tracking at that K_p [Nm].
    closed_loop_tau_f_rmse_nm: Option<f64>,
    /// Friction RMSE on the unseen tracking run against the label [Nm] (offline, `frictl eval`).
    offline_rmse_nm: Option<f64>,
    /// The same against the simulator's true friction [Nm].
    offline_rmse_true_nm: Option<f64>,
    /// Datasets the model was trained on (the protocol's first, then the on-policy rounds').
    datasets: Vec<String>,
}

/// One on-policy round `k` ≥ 1 (see `--onpolicy-rounds`): the current PINNs' minimum K_p and
/// offline error (the round k − 1 entry), on-policy runs around that K_p with them, labelled and
/// added to each joint's datasets, and training continued from them. Replaces `files[].fwt` and
/// `train_report` by the new models.
pub(super) fn onpolicy_round(
    r: &mut Runner,
    args: &Args,
    sizes: &Sizes,
    dirs: &Dirs,
    files: &mut [JointFiles],
    k: u32,
) -> anyhow::Result<RoundEntry> {
    let (plant_t0, _) = plant_t0_sets(dirs)?;
    let offsets = pinn_offsets_arg(files)?;
    let search_dir = dirs.experiments.join(format!("onpolicy_round{}", k - 1));
    r.stage(
        &format!("on-policy round {k}: min K_p of the round-{} PINN", k - 1),
        &["experiment"],
        &experiment::Args {
            seed: args.seed,
            iterations: sizes.iterations,
            periods: sizes.periods,
            out: search_dir.clone(),
            sets: plant_t0.clone(),
            ..pinn_experiment(experiment::Kind::MinKp, files, &offsets)?
        },
    )?;
    let ex: SuiteReport = read_typed(&search_dir.join("report.json"))?;
    let mut entry = RoundEntry {
        round: k - 1,
        joints: BTreeMap::new(),
    };
    let mut kp = vec![];
    for ((preset, joint), f) in JOINTS.iter().zip(files.iter()) {
        let cell = ex.joints.get(*joint).and_then(|c| c.get("PINN"));
        let min_kp = cell.and_then(|c| c.min_kp);
        let kp_centre = min_kp
            .map(|m| m.kp_for_runs())
            .filter(|v| v.is_finite() && *v > 0.0)
            .with_context(|| format!("{search_dir:?}: no minimum K_p for the {joint} PINN"))?;
        kp.push(format!("{preset}={kp_centre}"));
        let eval_json = dirs
            .eval
            .join(format!("{joint}_onpolicy_round{}.json", k - 1));
        r.stage(
            &format!("on-policy round {k}: eval {preset} round-{} PINN", k - 1),
            &["eval"],
            &eval::Args {
                datasets: vec![f.test_ds.clone()],
                pinns: vec![f.fwt.clone()],
                json: Some(eval_json.clone()),
                ..stage::defaults()?
            },
        )?;
        let ev: EvalReport = read_typed(&eval_json)?;
        let pinn = ev.models.get("pinn");
        entry.joints.insert(
            (*joint).to_owned(),
            RoundJoint {
                model: s(&f.fwt),
                min_kp,
                closed_loop_tau_f_rmse_nm: cell
                    .and_then(|c| c.track_at_min_kp)
                    .map(|t| t.friction_est_rmse_nm)
                    .filter(|v| v.is_finite()),
                offline_rmse_nm: pinn.and_then(|m| m.rmse_all),
                offline_rmse_true_nm: pinn.and_then(|m| m.rmse_true_all),
                datasets: f.datasets.iter().map(|d| s(d)).collect(),
            },
        );
    }
    let rec_dir = dirs.data.join(format!("onpolicy{k}"));
    r.stage(
        &format!("on-policy round {k}: record (both joints, PINN compensating)"),
        &["experiment"],
        &experiment::Args {
            kp: Some(kp.join(",")),
            record_runs: sizes.onpolicy_runs as usize,
            periods: sizes.periods,
            seed: args.seed + 1000 * u64::from(k),
            out: rec_dir.clone(),
            sets: plant_t0,
            ..pinn_experiment(experiment::Kind::Record, files, &offsets)?
        },
    )?;
    for ((preset, joint), f) in JOINTS.iter().zip(files.iter_mut()) {
        let raw = rec_dir.join(format!("{joint}_onpolicy.csv"));
        let ds = dirs.data.join(format!("{joint}_onpolicy{k}_ds.csv"));
        r.stage(
            &format!("on-policy round {k}: preprocess {preset}"),
            &["preprocess"],
            &preprocess_args(args, &raw, &ds)?,
        )?;
        std::fs::remove_file(&raw).ok();
        f.datasets.push(ds);
        continue_training(r, args, sizes, dirs, f, preset, joint, k)?;
    }
    Ok(entry)
}

/// Round `k`'s training of one joint: from its current PINN (`--init`) on every dataset so far
/// (`f.datasets`), for the sizes' on-policy epochs and rate, with the Δθ offset the first model was
/// trained with (frictiond runs one fixed offset per joint). Replaces `f.fwt` and `f.train_report`
/// by `{joint}_onpolicy{k}.fwt` and its report; `preset` names the stage and the train settings.
#[allow(clippy::too_many_arguments)]
pub(super) fn continue_training(
    r: &mut Runner,
    args: &Args,
    sizes: &Sizes,
    dirs: &Dirs,
    f: &mut JointFiles,
    preset: &str,
    joint: &str,
    k: u32,
) -> anyhow::Result<()> {
    let offset = match pinn_offset_arg(&f.train_report)?.as_str() {
        "enable" => "chunk".to_owned(),
        v => v.to_owned(),
    };
    let fwt = dirs.models.join(format!("{joint}_onpolicy{k}.fwt"));
    let report = dirs.models.join(format!("{joint}_onpolicy{k}_train.json"));
    let datasets: Vec<&Path> = f.datasets.iter().map(PathBuf::as_path).collect();
    let mut a = train_args(
        sizes,
        args.seed,
        preset,
        &datasets,
        [&f.scv, &fwt, &report],
        sizes.onpolicy_epochs,
    )?;
    a.init = Some(f.fwt.clone());
    a.delta_theta_offset = offset.parse().map_err(|e| {
        anyhow::anyhow!("Δθ offset {offset:?} of {}: {e}", f.train_report.display())
    })?;
    if let Some(lr) = sizes.onpolicy_lr {
        a.lr = lr;
    }
    r.stage(
        &format!("on-policy round {k}: train {preset} (--init)"),
        &["train"],
        &a,
    )?;
    f.fwt = fwt;
    f.train_report = report;
    Ok(())
}

/// The last round's entry: the final PINNs' results from the experiments and the evaluation.
pub(super) fn final_round(
    rounds: u32,
    files: &[JointFiles],
    per_joint: &BTreeMap<String, JointEntry>,
) -> RoundEntry {
    let joints = JOINTS
        .iter()
        .zip(files)
        .map(|((_, joint), f)| {
            let pinn = per_joint.get(*joint).and_then(|e| e.models.get("PINN"));
            let cl = pinn.and_then(|m| m.closed_loop.as_ref());
            let ev = pinn.and_then(|m| m.eval.flatten());
            (
                (*joint).to_owned(),
                RoundJoint {
                    model: s(&f.fwt),
                    min_kp: cl.and_then(|c| c.min_kp),
                    closed_loop_tau_f_rmse_nm: cl.and_then(|c| c.closed_loop_tau_f_rmse_nm),
                    offline_rmse_nm: ev.and_then(|m| m.rmse_all),
                    offline_rmse_true_nm: ev.and_then(|m| m.rmse_true_all),
                    datasets: f.datasets.iter().map(|d| s(d)).collect(),
                },
            )
        })
        .collect();
    RoundEntry {
        round: rounds,
        joints,
    }
}

/// The on-policy rounds as a markdown table (with the oracle's closed-loop τ̂_F error for scale).
pub(super) fn onpolicy_md(
    rounds: &[RoundEntry],
    per_joint: &BTreeMap<String, JointEntry>,
) -> String {
    let mut md = String::from(
        "\n## On-policy rounds (DAgger)\n\nRound 0 is the PINN trained on the open-loop protocol; each round \
         adds closed-loop runs recorded with the previous round's PINN compensating and continues its \
         training on the union. Closed-loop τ̂_F error: RMSE of τ̂_F/kfc against the true friction \
         while tracking at the model's minimum K_p; offline: on the unseen tracking run (label, truth \
         in parentheses).\n\n| joint | round | min K_p | closed-loop τ̂_F error [Nm] | oracle's [Nm] | offline RMSE [Nm] | datasets |\n|---|---|---|---|---|---|---|\n",
    );
    let f = |v: Option<f64>| v.map_or("–".to_owned(), |x| format!("{x:.3}"));
    for (_, joint) in JOINTS {
        let oracle = per_joint
            .get(joint)
            .and_then(|e| e.models.get(ORACLE_LABEL))
            .and_then(|m| m.closed_loop.as_ref())
            .and_then(|c| c.closed_loop_tau_f_rmse_nm);
        for re in rounds {
            let Some(j) = re.joints.get(joint) else {
                continue;
            };
            let kp = match j.min_kp {
                Some(MinKp::Found { kp, .. }) => {
                    frictionless_experiment::search::sig3(kp).to_string()
                }
                Some(other) => format!("{other:?}"),
                None => "–".into(),
            };
            md += &format!(
                "| {joint} | {} | {kp} | {} | {} | {} ({}) | {} |\n",
                re.round,
                f(j.closed_loop_tau_f_rmse_nm),
                f(oracle),
                f(j.offline_rmse_nm),
                f(j.offline_rmse_true_nm),
                j.datasets.len()
            );
        }
    }
    md
}

//! `frictl search` with 3 tiny trials (2 epochs each, 2 in parallel) on a small simulated dataset:
//! the results table is complete and sorted by validation RMSE, `best.fwt` is the best trial's model,
//! the hyper-parameters are in the paper's ranges, and a resumed search runs only the missing trials.

use std::path::{Path, PathBuf};

use crate::util::{frictl, frictl_ok as ok, s, small_acquire_args};
use frictionless_train::search::{SearchSpace, TrialResult, draw, read_results};

fn dataset(dir: &Path) -> (PathBuf, PathBuf) {
    ok(&small_acquire_args("ankle_roll", "2", dir, "run", &[]));
    let ds = dir.join("ds.csv");
    ok(&[
        "preprocess",
        s(&dir.join("run.csv")),
        "--out",
        s(&ds),
        "--link-from-sidecar",
    ]);
    let scv = dir.join("scv.json");
    ok(&["fit", "scv-code", s(&ds), "--json", s(&scv)]);
    (ds, scv)
}

#[test]
fn three_tiny_trials_then_resume() {
    let dir = crate::util::scratch("frictl-search-cli");
    std::fs::create_dir_all(&dir).unwrap();
    let (ds, scv) = dataset(&dir);
    let out = dir.join("search");
    let search = |trials: &str, resume: bool| {
        let mut a = vec![
            "search",
            "--dataset",
            s(&ds),
            "--scv",
            s(&scv),
            "--trials",
            trials,
            "--out",
            s(&out),
            "--parallel",
            "2",
            "--threads",
            "2",
            "--epochs",
            "2",
            "--seed",
            "5",
            "--quiet",
        ];
        if resume {
            a.push("--resume");
        }
        frictl(&a)
    };
    let r = search("3", false);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));

    let lines = read_results(&out.join("results.jsonl")).unwrap();
    assert_eq!(lines.len(), 3);
    let mut idx: Vec<usize> = lines.iter().map(|t| t.params.trial).collect();
    idx.sort();
    assert_eq!(idx, vec![0, 1, 2]);
    let space = SearchSpace::default();
    for t in &lines {
        assert_eq!(t.status, "ok", "{:?}", t.error);
        assert_eq!(
            t.params,
            draw(&space, 5, t.params.trial),
            "drawn from (seed, index)"
        );
        let p = &t.params;
        assert!((3000..=5000).contains(&p.batch_size));
        assert!(p.hidden.iter().all(|h| (150..=300).contains(h)));
        assert!((1e-5..=1e-3).contains(&p.lr));
        assert!((3..=30).contains(&p.history));
        assert!((0.1..=0.5).contains(&p.lambda) && (0.01..=0.1).contains(&p.dropout));
        assert!(t.val_rmse_nm.unwrap() > 0.0 && t.test_rmse_nm.unwrap() > 0.0);
        assert_eq!(t.epochs_run, 2);
    }

    // results.json is sorted by validation RMSE; results.csv has the same order.
    let ranked: Vec<TrialResult> =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let vals: Vec<f64> = ranked.iter().map(|t| t.val_rmse_nm.unwrap()).collect();
    assert!(vals.windows(2).all(|w| w[0] <= w[1]), "sorted: {vals:?}");
    let mut csv = csv::Reader::from_path(out.join("results.csv")).unwrap();
    let csv_trials: Vec<usize> = csv
        .records()
        .map(|r| r.unwrap()[1].parse().unwrap())
        .collect();
    let json_trials: Vec<usize> = ranked.iter().map(|t| t.params.trial).collect();
    assert_eq!(csv_trials, json_trials);

    // best.fwt is the best trial's model, and it is valid.
    let best = &ranked[0];
    let best_bytes = std::fs::read(out.join("best.fwt")).unwrap();
    assert!(best_bytes == std::fs::read(out.join(best.model.as_ref().unwrap())).unwrap());
    let m = frictionless::weights::read_file(&out.join("best.fwt")).unwrap();
    assert_eq!(m.meta.features.history, best.params.history);
    assert!((m.meta.training.val_rmse_nm as f64 - vals[0]).abs() < 1e-4 * vals[0].max(1.0));

    // Every trial is timed on this CPU, and pick.fwt is the fastest trial within 1.05× the best
    // validation RMSE (the default --max-rmse-ratio).
    assert!(
        ranked
            .iter()
            .all(|t| t.hot_us.is_some_and(|v| v > 0.0) && t.cold_us.is_some_and(|v| v > 0.0))
    );
    let pick = frictionless_train::search::cheapest_within(&ranked, 1.05).unwrap();
    assert!(pick.val_rmse_nm.unwrap() <= 1.05 * vals[0]);
    assert!(
        std::fs::read(out.join("pick.fwt")).unwrap()
            == std::fs::read(out.join(pick.model.as_ref().unwrap())).unwrap()
    );

    // Without --resume the directory is refused; with it only trial 3 runs.
    let again = search("3", false);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--resume"));
    let r = search("4", true);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let lines2 = read_results(&out.join("results.jsonl")).unwrap();
    assert_eq!(lines2.len(), 4, "one new trial appended");
    assert_eq!(&lines2[..3], &lines[..], "finished trials untouched");
    assert_eq!(lines2[3].params.trial, 3);
    let r = search("4", true);
    assert!(r.status.success());
    assert_eq!(
        read_results(&out.join("results.jsonl")).unwrap().len(),
        4,
        "nothing left to run"
    );
}

/// `frictl search` on the tiny network ranges (fast trials) with `extra` arguments.
fn tiny_search(
    ds: &Path,
    scv: &Path,
    out: &Path,
    trials: &str,
    extra: &[&str],
) -> std::process::Output {
    let mut a = vec![
        "search",
        "--dataset",
        s(ds),
        "--scv",
        s(scv),
        "--trials",
        trials,
        "--out",
        s(out),
        "--parallel",
        "1",
        "--threads",
        "1",
        "--epochs",
        "1",
        "--quiet",
    ];
    for (k, v) in [("--hidden-range", "8,16"), ("--batch-range", "256,512")] {
        if !extra.contains(&k) {
            a.extend_from_slice(&[k, v]);
        }
    }
    a.extend_from_slice(extra);
    frictl(&a)
}

#[test]
fn a_failed_trial_fails_the_search_and_resume_runs_it_again() {
    // Before: a trial that could not write its model (as on a full disk) was recorded and the
    // search exited 0; `--resume` skipped it for good.
    let dir = crate::util::scratch("frictl-search-failed");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (ds, scv) = dataset(&dir);
    let out = dir.join("search");
    // Trial 1's model path is a directory: its outputs cannot be written.
    let blocked = out.join("trials/trial_0001.fwt");
    std::fs::create_dir_all(&blocked).unwrap();
    let r = tiny_search(&ds, &scv, &out, "2", &[]);
    let err = String::from_utf8_lossy(&r.stderr).into_owned();
    assert!(!r.status.success(), "a failed trial exited 0:\n{err}");
    assert!(
        err.contains("1 of 2 trial(s) failed") && err.contains("--resume"),
        "{err}"
    );
    let rec = read_results(&out.join("results.jsonl")).unwrap();
    let status = |k: usize| -> Vec<String> {
        read_results(&out.join("results.jsonl"))
            .unwrap()
            .iter()
            .filter(|t| t.params.trial == k)
            .map(|t| t.status.clone())
            .collect()
    };
    assert_eq!(rec.len(), 2);
    assert_eq!(status(1), ["failed"]);
    // The cause gone, `--resume` runs the failed trial again (only it) and succeeds.
    std::fs::remove_dir(&blocked).unwrap();
    let r = tiny_search(&ds, &scv, &out, "2", &["--resume"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(status(0), ["ok"], "the ok trial is not run again");
    assert_eq!(status(1), ["failed", "ok"]);
    let ranked: Vec<TrialResult> =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert!(ranked.iter().all(|t| t.status == "ok") && ranked.len() == 2);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_search_directory_has_one_owner_and_bad_settings_are_refused_before_any_trial() {
    let dir = crate::util::scratch("frictl-search-lock");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (ds, scv) = dataset(&dir);
    let out = dir.join("search");
    std::fs::create_dir_all(&out).unwrap();
    // Another owner holds the directory's lock: refused, nothing written (before: two searches
    // wrote one results table).
    let lock = std::fs::File::create(out.join(".search.lock")).unwrap();
    lock.lock().unwrap();
    let r = tiny_search(&ds, &scv, &out, "1", &[]);
    let err = String::from_utf8_lossy(&r.stderr).into_owned();
    assert!(!r.status.success(), "{err}");
    assert!(
        err.contains("another `frictl search`") && err.contains(".search.lock"),
        "{err}"
    );
    assert!(!out.join("results.jsonl").exists() && !out.join("search.json").exists());
    let r = tiny_search(&ds, &scv, &out, "1", &["--only-trials", "0"]);
    assert!(!r.status.success(), "a worker ran beside the search");
    drop(lock);

    // Settings the trainer refuses at either end of a range, and a bad pick ratio, are refused
    // before the first trial, naming the option and the limit (before: every trial failed and the
    // search exited 0).
    for (args, says, limit) in [
        (
            &["--history-range", "3,65"][..],
            "--history-range 3,65",
            "64",
        ),
        (
            &["--hidden-range", "8,2000"],
            "--hidden-range 8,2000",
            "1..=1024",
        ),
        (
            &["--dropout-range", "0.1,1.5"],
            "--dropout-range 0.1,1.5",
            "[0, 1)",
        ),
        (
            &["--lambda-range", "0.2,1.5"],
            "--lambda-range 0.2,1.5",
            "[0, 1]",
        ),
        (
            &["--lambda-range=-0.5,0.3"],
            "--lambda-range -0.5,0.3",
            "[0, 1]",
        ),
        (&["--max-rmse-ratio", "0"], "--max-rmse-ratio 0", "≥ 1"),
        (&["--max-rmse-ratio", "nan"], "--max-rmse-ratio NaN", "≥ 1"),
    ] {
        let bad = dir.join("bad");
        let r = tiny_search(&ds, &scv, &bad, "1", args);
        let err = String::from_utf8_lossy(&r.stderr).into_owned();
        assert!(!r.status.success(), "{args:?} accepted");
        assert!(err.contains(says) && err.contains(limit), "{args:?}: {err}");
        assert!(!bad.join("results.jsonl").exists(), "{args:?}: a trial ran");
    }
    // A trial count that cannot be held is refused by the option's bound (before: OOM-killed).
    let r = tiny_search(&ds, &scv, &dir.join("huge"), "1e11", &[]);
    let err = String::from_utf8_lossy(&r.stderr).into_owned();
    assert!(
        !r.status.success() && err.contains("--trials") && err.contains("bound"),
        "{err}"
    );
    // The directory free again, the search runs.
    let r = tiny_search(&ds, &scv, &out, "1", &[]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    std::fs::remove_dir_all(&dir).unwrap();
}

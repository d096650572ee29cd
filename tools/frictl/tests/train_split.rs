//! The train/validation/test split is by whole chunks: on two simulated datasets (`frictl acquire` →
//! `frictl preprocess`), no chunk is in two sets, every sample of a set comes from that set's chunks,
//! and no input window reaches into another chunk (hold-zero: full windows inside the chunk;
//! zero-pad: the slots before the chunk start are 0). The split is seeded and recorded in the report.

use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

use crate::util::{frictl_ok as frictl, s, small_acquire_args};
use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
use frictionless_train::data::{ChunkKey, DeltaThetaOffset, SplitSpec};
use frictionless_train::pipeline::{self, Sources};

struct Fixture {
    dir: PathBuf,
    datasets: Vec<PathBuf>,
    scv: PathBuf,
}

/// Two ankle-roll runs (seeds 4 and 5), preprocessed, and an SCV fit of the first.
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = crate::util::scratch("frictl-train-split");
        std::fs::create_dir_all(&dir).unwrap();
        let mut datasets = Vec::new();
        for seed in ["4", "5"] {
            let name = format!("run{seed}");
            frictl(&small_acquire_args("ankle_roll", seed, &dir, &name, &[]));
            let ds = dir.join(format!("ds{seed}.csv"));
            frictl(&[
                "preprocess",
                s(&dir.join(format!("{name}.csv"))),
                "--out",
                s(&ds),
                "--link-from-sidecar",
            ]);
            datasets.push(ds);
        }
        let scv = dir.join("scv.json");
        frictl(&["fit", "scv-code", s(&datasets[0]), "--json", s(&scv)]);
        Fixture { dir, datasets, scv }
    })
}

fn sources() -> Sources {
    pipeline::load_sources(&fixture().datasets).unwrap()
}

#[test]
fn no_chunk_in_two_sets_and_no_window_straddles_chunks() {
    let f = fixture();
    let src = sources();
    let scv = pipeline::load_scv(&f.scv).unwrap();
    let all = pipeline::chunks_with_valid_rows(&src);
    assert!(
        all.iter().any(|k| k.dataset == 1) && all.len() >= 8,
        "two datasets with several chunks: {all:?}"
    );
    for seed in 0..6 {
        let spec = SplitSpec {
            val_frac: 0.2,
            test_frac: 0.2,
            seed,
            test_chunks: None,
        };
        let split = pipeline::split_for(&src, &spec).unwrap();
        let sets = [&split.train, &split.val, &split.test];
        for (i, a) in sets.iter().enumerate() {
            assert!(!a.is_empty(), "seed {seed}: set {i} is empty");
            for b in &sets[i + 1..] {
                assert!(
                    a.iter().all(|k| !b.contains(k)),
                    "seed {seed}: a chunk is in two sets"
                );
            }
        }
        let mut union: Vec<ChunkKey> = sets.iter().flat_map(|s| s.iter().copied()).collect();
        union.sort();
        assert_eq!(union, all, "seed {seed}: every chunk in exactly one set");

        for (warmup, h) in [(WarmupPolicy::HoldZero, 7), (WarmupPolicy::ZeroPad, 4)] {
            let fs = FeatureSpec {
                set: FeatureSet::DeltaThetaJointVel,
                history: h,
                temperature: false,
            };
            let p =
                pipeline::prepare(&src, &scv, &split, &fs, warmup, DeltaThetaOffset::Run).unwrap();
            for (set, chunks) in [
                (&p.train, &split.train),
                (&p.val, &split.val),
                (&p.test, &split.test),
            ] {
                assert!(!set.is_empty());
                for (i, &(d, row)) in set.rows.iter().enumerate() {
                    let ds = &src.list[d as usize].data;
                    let chunk = ds.chunk[row];
                    assert!(
                        chunks.contains(&ChunkKey { dataset: d, chunk }),
                        "sample from chunk {d}:{chunk} outside its set"
                    );
                    assert!(ds.valid[row], "targets are valid rows only");
                    // Rows of the window: row − (H−1) … row.
                    let in_chunk = (0..h)
                        .take_while(|&age| age <= row && ds.chunk[row - age] == chunk)
                        .count();
                    match warmup {
                        WarmupPolicy::HoldZero => assert_eq!(
                            in_chunk, h,
                            "window of {d}:{row} straddles a chunk boundary"
                        ),
                        WarmupPolicy::ZeroPad => {
                            let x = &set.x[i * fs.n_inputs()..(i + 1) * fs.n_inputs()];
                            for b in 0..2 {
                                for j in 0..h - in_chunk {
                                    assert_eq!(
                                        x[b * h + j],
                                        0.0,
                                        "slot before the chunk start of {d}:{row} is not zero"
                                    );
                                }
                            }
                        }
                    }
                }
            }
            // Train and test never share a sample (a set: the row lists are tens of thousands long).
            let train_rows: std::collections::HashSet<_> = p.train.rows.iter().collect();
            assert!(p.test.rows.iter().all(|r| !train_rows.contains(r)));
        }
    }
}

#[test]
fn split_is_seeded_and_recorded_in_the_report() {
    let f = fixture();
    let src = sources();
    let spec = |seed| SplitSpec {
        val_frac: 0.15,
        test_frac: 0.15,
        seed,
        test_chunks: None,
    };
    assert_eq!(
        pipeline::split_for(&src, &spec(1)).unwrap(),
        pipeline::split_for(&src, &spec(1)).unwrap()
    );
    let run = |tag: &str, extra: &[&str]| -> serde_json::Value {
        let out = f.dir.join(format!("{tag}.fwt"));
        let mut args = vec![
            "train",
            "--dataset",
            s(&f.datasets[0]),
            "--dataset",
            s(&f.datasets[1]),
            "--scv",
            s(&f.scv),
            "--out",
            s(&out),
            "--history",
            "4",
            "--hidden",
            "8,8",
            "--epochs",
            "1",
            "--batch",
            "2048",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        frictl(&args);
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("train.json")).unwrap())
            .unwrap()
    };
    let r = run("seed1", &["--seed", "1"]);
    let want = pipeline::split_for(&src, &spec(1)).unwrap();
    let keys =
        |v: &serde_json::Value| -> Vec<ChunkKey> { serde_json::from_value(v.clone()).unwrap() };
    assert_eq!(keys(&r["split"]["train"]), want.train);
    assert_eq!(keys(&r["split"]["val"]), want.val);
    assert_eq!(keys(&r["split"]["test"]), want.test);
    assert_eq!(r["datasets"].as_array().unwrap().len(), 2);

    // Explicit test chunks from both datasets.
    let r = run("explicit", &["--test-chunks", "1:2,0:3"]);
    assert_eq!(
        keys(&r["split"]["test"]),
        vec![
            ChunkKey {
                dataset: 0,
                chunk: 3
            },
            ChunkKey {
                dataset: 1,
                chunk: 2
            }
        ]
    );
    assert!(
        keys(&r["split"]["train"])
            .iter()
            .chain(&keys(&r["split"]["val"]))
            .all(|k| *k
                != ChunkKey {
                    dataset: 0,
                    chunk: 3
                }
                && *k
                    != ChunkKey {
                        dataset: 1,
                        chunk: 2
                    })
    );
}

/// `--test-run` / `--test-dataset` hold out whole runs: every chunk of the held-out run is test, the
/// validation chunks come from the training runs only, and the report records the training range.
#[test]
fn held_out_runs_are_the_test_set_and_validation_comes_from_the_training_runs() {
    let f = fixture();
    let src = sources();
    let with_rows = pipeline::chunks_with_valid_rows(&src);
    let of = |d: u32| -> Vec<ChunkKey> {
        with_rows
            .iter()
            .copied()
            .filter(|k| k.dataset == d)
            .collect()
    };
    assert_eq!(
        pipeline::held_out_chunks(&src, &["ds5".to_owned()], &[]).unwrap(),
        of(1)
    );
    let e = pipeline::held_out_chunks(&src, &["nope".to_owned()], &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nope") && e.contains("ds4") && e.contains("ds5"),
        "{e}"
    );

    let keys =
        |v: &serde_json::Value| -> Vec<ChunkKey> { serde_json::from_value(v.clone()).unwrap() };
    let train = |tag: &str, data: &[&str]| -> serde_json::Value {
        let out = f.dir.join(format!("{tag}.fwt"));
        let mut args = vec!["train"];
        args.extend_from_slice(data);
        args.extend_from_slice(&[
            "--scv",
            s(&f.scv),
            "--out",
            s(&out),
            "--history",
            "4",
            "--hidden",
            "8,8",
            "--epochs",
            "1",
            "--batch",
            "2048",
            "--val-frac",
            "0.3",
            "--quiet",
        ]);
        frictl(&args);
        serde_json::from_str(&std::fs::read_to_string(out.with_extension("train.json")).unwrap())
            .unwrap()
    };
    let by_run = train(
        "heldrun",
        &[
            "--dataset",
            s(&f.datasets[0]),
            "--dataset",
            s(&f.datasets[1]),
            "--test-run",
            "ds5",
        ],
    );
    let by_file = train(
        "heldfile",
        &[
            "--dataset",
            s(&f.datasets[0]),
            "--test-dataset",
            s(&f.datasets[1]),
        ],
    );
    for r in [&by_run, &by_file] {
        assert_eq!(keys(&r["split"]["test"]), of(1));
        let val = keys(&r["split"]["val"]);
        assert!(!val.is_empty());
        assert!(
            val.iter()
                .chain(&keys(&r["split"]["train"]))
                .all(|k| k.dataset == 0),
            "validation and training only from the training run"
        );
        let range: frictionless_dataset::MotionRange =
            serde_json::from_value(r["training_range"].clone()).unwrap();
        assert!(range.rows > 0 && range.sdot_rad_s[0] < 0.0 && range.sdot_rad_s[1] > 0.0);
    }
    assert_eq!(by_run["split"], by_file["split"]);

    // `frictl fit --test-run` leaves the run out (here: the whole file, so nothing is left to fit) and
    // names the runs there are for an unknown name.
    for (name, want) in [("ds5", "0 samples selected"), ("nope", "runs: ds5")] {
        let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
            .args(["fit", "scv-code", s(&f.datasets[1]), "--test-run", name])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(want), "{name}: {err}");
    }
}

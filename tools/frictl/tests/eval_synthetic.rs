//! `frictl eval` on synthetic datasets whose label is known by construction.
//!
//! - label = SCV(ṡ) + N(0, σ): the true SCV scores RMSE ≈ σ against the label and 0 against the truth
//!   column, "none" is far worse, and the sliding/stick split counts add up;
//! - label = c·ṡ + d·Δθ (Δθ latched once at the first row of the dataset, or at each chunk start) +
//!   noise, and a PINN file whose network computes exactly c·ṡ_newest + d·Δθ_newest: the PINN, run
//!   through the daemon's `PinnEstimator`, scores ≈ σ under the matching `delta_theta_offset` option,
//!   which it can only do if the history, the newest-sample index and the Δθ latch are the daemon's
//!   (and it is far off under the other latch); with `hold_zero` the first H−1 rows of each chunk are
//!   skipped for every model;
//! - the `frictl eval` binary writes the JSON report (the keys `frictl demo` reads) and valid PNG
//!   figures, and `--test-only` keeps only the train report's test chunks.

use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;

use frictionless::features::{FeatureSet, FeatureSpec, WarmupPolicy};
use frictionless::friction::{ScvParams, StaticFriction, paper};
use frictionless::mlp::{Activation, DenseLayer, MlpWeights, Normalisation, StorageDtype};
use frictionless::model::JointModel;
use frictionless::units::GearRatio;
use frictionless::weights::{ModelFile, ModelMeta, TrainingMeta};
use frictionless_dataset::Dataset;
use frictionless_eval::{EvalOptions, ModelSpec, evaluate};
use frictionless_train::data::DeltaThetaOffset;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const R: f64 = -160.0;
const SIGMA: f64 = 0.1;
const CHUNK_ROWS: usize = 4000;

/// Chunks of sine motion (different amplitude/frequency per chunk) with a deflection Δ(t), so
/// θ = r·s − Δθ with Δθ = 3·sin(…) + per-chunk offset [motor rad]. `label(ṡ, Δθ_rel)` gives the
/// noiseless friction, Δθ_rel relative to the latch instant of `latch` (`Run`: the first row,
/// `Chunk`: each chunk's first row); the label column adds N(0, σ) noise, the truth column is
/// noiseless.
fn dataset(label: &dyn Fn(f64, f64) -> f64, seed: u64, latch: DeltaThetaOffset) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, SIGMA).unwrap();
    let mut ds = Dataset::default();
    for c in 0..3u32 {
        let (amp, f) = (0.1 + 0.05 * f64::from(c), 0.5 + 0.25 * f64::from(c));
        let w = 2.0 * std::f64::consts::PI * f;
        let dth0 = 5.0 * f64::from(c) - 2.0;
        for k in 0..CHUNK_ROWS {
            let t = k as f64 * 1e-3;
            let s = amp * (w * t).sin();
            let sdot = amp * w * (w * t).cos();
            let dth = dth0 + 3.0 * (2.0 * w * t + 0.3).sin();
            let dth_rel = match latch {
                DeltaThetaOffset::Chunk => dth - (dth0 + 3.0 * 0.3f64.sin()),
                DeltaThetaOffset::Run => dth - (-2.0 + 3.0 * 0.3f64.sin()),
                DeltaThetaOffset::Fixed(_) => unreachable!("not used here"),
            };
            let truth = label(sdot, dth_rel);
            ds.time_s.push(10.0 * f64::from(c) + t);
            ds.chunk.push(c);
            ds.source_chunk.push(c);
            ds.active.push(true);
            ds.valid.push(true);
            ds.s_rad.push(s);
            ds.sdot_rad_s.push(sdot);
            ds.sddot_rad_s2.push(-amp * w * w * (w * t).sin());
            ds.theta_motor_rad.push(R * s - dth);
            ds.delta_theta_motor_rad.push(dth);
            ds.omega_motor_rad_s.push(R * sdot);
            ds.i_meas_a.push(0.0);
            ds.i_filt_a.push(0.0);
            ds.tau_id_nm.push(0.0);
            ds.tau_f_label_nm.push(truth + noise.sample(&mut rng));
            ds.temperature_c.push(f64::NAN);
            ds.tau_f_true_nm.get_or_insert_with(Vec::new).push(truth);
            ds.phi_ddot_rad_s2.get_or_insert_with(Vec::new).push(0.0);
        }
    }
    ds
}

const C_NM_S: f32 = 2.0;
const D_NM: f32 = 0.25;
const H: usize = 5;

/// A `.fwt` model computing c·ṡ_newest + d·Δθ_newest with ReLU pairs (relu(x) − relu(−x) = x).
fn linear_pinn() -> ModelFile {
    let n = 2 * H;
    let mut w1 = vec![0f32; 4 * n];
    let (dth, sdot) = (H - 1, 2 * H - 1); // newest sample of each block
    w1[dth] = D_NM;
    w1[n + dth] = -D_NM;
    w1[2 * n + sdot] = C_NM_S;
    w1[3 * n + sdot] = -C_NM_S;
    ModelFile {
        meta: ModelMeta {
            joint_name: "l_ankle_roll".into(),
            gear_ratio: GearRatio::new(R).unwrap(),
            kt_nm_per_a: 0.0665,
            features: FeatureSpec {
                set: FeatureSet::DeltaThetaJointVel,
                history: H,
                temperature: false,
            },
            scv: None,
            training: TrainingMeta::unknown("eval test", 0),
        },
        dtype: StorageDtype::F32,
        mlp: MlpWeights {
            norm: Normalisation::identity(n),
            layers: vec![
                DenseLayer {
                    n_in: n,
                    n_out: 4,
                    weight: w1,
                    bias: vec![0.0; 4],
                    activation: Activation::Relu,
                },
                DenseLayer {
                    n_in: 4,
                    n_out: 1,
                    weight: vec![1.0, -1.0, 1.0, -1.0],
                    bias: vec![0.0],
                    activation: Activation::Identity,
                },
            ],
        },
    }
}

fn scv() -> ScvParams {
    paper::SCV_ANKLE_ROLL
}

#[test]
fn scv_label_scores_the_noise_and_none_is_far() {
    let m = scv();
    let ds = dataset(&|v, _| m.torque_nm(v), 1, DeltaThetaOffset::Run);
    let models = [
        ModelSpec::none(),
        ModelSpec::static_model("scv", JointModel::Scv(m)),
    ];
    let ev = evaluate("synthetic", &ds, &models, None, &EvalOptions::default()).unwrap();
    let none = ev.sums[0].metrics();
    let s = ev.sums[1].metrics();
    println!("none {none:?}\nscv {s:?}");
    assert_eq!(s.n_samples, ds.len());
    assert_eq!(s.n_sliding + s.n_stick, s.n_samples);
    assert!(s.n_stick > 0 && s.n_sliding > s.n_stick);
    for r in [s.rmse_all, s.rmse_sliding, s.rmse_stick] {
        let r = r.unwrap();
        assert!(
            (r - SIGMA).abs() < 0.15 * SIGMA,
            "SCV RMSE {r} vs noise σ {SIGMA}"
        );
    }
    assert!(s.rmse_true_all.unwrap() < 1e-9);
    assert!(none.rmse_all.unwrap() > 5.0 * SIGMA, "none {none:?}");
    assert!(none.rmse_true_all.unwrap() > 5.0 * SIGMA);
    // Sliding rows are where the friction is large; stick rows hold the breakaway transition.
    assert!(none.rmse_sliding.unwrap() > none.rmse_stick.unwrap());
}

#[test]
fn pinn_runs_like_the_daemon_with_the_run_or_the_chunk_latch() {
    let lin = |v: f64, d: f64| f64::from(C_NM_S) * v + f64::from(D_NM) * d;
    let file = linear_pinn();
    let models = [
        ModelSpec::none(),
        ModelSpec::static_model("scv", JointModel::Scv(scv())),
        ModelSpec::pinn("pinn", &file, WarmupPolicy::HoldZero).unwrap(),
    ];
    let opts = |latch| EvalOptions {
        delta_theta_offset: latch,
        ..EvalOptions::default()
    };
    assert_eq!(
        EvalOptions::default().delta_theta_offset,
        DeltaThetaOffset::Run
    );
    for (latch, other) in [
        (DeltaThetaOffset::Run, DeltaThetaOffset::Chunk),
        (DeltaThetaOffset::Chunk, DeltaThetaOffset::Run),
    ] {
        let ds = dataset(&lin, 2, latch);
        let ev = evaluate("synthetic", &ds, &models, None, &opts(latch)).unwrap();
        let p = ev.sums[2].metrics();
        let scv_m = ev.sums[1].metrics();
        println!("{latch}: pinn {p:?}\nscv {scv_m:?}");
        // hold_zero: the first H−1 rows of each of the 3 chunks are skipped, for every model.
        assert_eq!(p.n_samples, ds.len() - 3 * (H - 1));
        assert_eq!(scv_m.n_samples, p.n_samples);
        let r = p.rmse_all.unwrap();
        assert!((r - SIGMA).abs() < 0.15 * SIGMA, "{latch}: PINN RMSE {r}");
        assert!(p.rmse_true_all.unwrap() < 1e-3, "{latch}: {p:?}");
        assert!(scv_m.rmse_all.unwrap() > 3.0 * r);
        // Warm-up rows predict 0 (the daemon's hold_zero), then the network's value.
        let pred = &ev.predictions[2];
        assert_eq!(pred[0], 0.0);
        assert_eq!(pred[CHUNK_ROWS + H - 2], 0.0);
        let k = CHUNK_ROWS + 100;
        let want = ds.tau_f_true_nm.as_ref().unwrap()[k];
        assert!((pred[k] - want).abs() < 1e-3 * (1.0 + want.abs()));
        // The other latch shifts chunks 1 and 2 by d·(5 motor rad per chunk): far off.
        let wrong = evaluate("synthetic", &ds, &models, None, &opts(other)).unwrap();
        let rw = wrong.sums[2].metrics().rmse_all.unwrap();
        assert!(
            rw > 5.0 * r,
            "{latch} data under the {other} latch: {rw} vs {r}"
        );
    }
}

fn png_size(path: &Path) -> (u32, u32) {
    let f = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut dec = png::Decoder::new(std::io::BufReader::new(f))
        .read_info()
        .unwrap_or_else(|e| panic!("{} is not a PNG: {e}", path.display()));
    let mut buf = vec![0; dec.output_buffer_size()];
    let info = dec.next_frame(&mut buf).unwrap();
    // Not a blank image: more than one distinct byte value.
    let distinct: BTreeSet<u8> = buf[..info.buffer_size()].iter().copied().collect();
    assert!(distinct.len() > 2, "{} looks blank", path.display());
    (info.width, info.height)
}

#[test]
fn cli_writes_report_and_figures_and_filters_test_chunks() {
    let dir = crate::util::scratch("eval_cli");
    std::fs::create_dir_all(&dir).unwrap();
    let lin = |v: f64, d: f64| f64::from(C_NM_S) * v + f64::from(D_NM) * d;
    let ds = dataset(&lin, 3, DeltaThetaOffset::Run);
    let csv = dir.join("heldout.csv");
    ds.write_csv(&csv).unwrap();
    let pinn = dir.join("m.fwt");
    frictionless::weights::write_file(&pinn, &linear_pinn()).unwrap();
    let scv_json = dir.join("scv.json");
    std::fs::write(
        &scv_json,
        serde_json::json!({"model": "Scv", "params": scv()}).to_string(),
    )
    .unwrap();
    let cv_json = dir.join("cv.json");
    std::fs::write(
        &cv_json,
        serde_json::json!({"model": "Cv", "params": paper::CV_ANKLE_ROLL}).to_string(),
    )
    .unwrap();
    let report = dir.join("train.json");
    std::fs::write(
        &report,
        serde_json::json!({
            "datasets": [{"path": "elsewhere/train.csv", "sha256": "00"}, {"path": csv.display().to_string()}],
            "split": {"test": [{"dataset": 1, "chunk": 2}, {"dataset": 0, "chunk": 0}]},
            "epochs": [
                {"epoch": 1, "train_loss": 3.0, "val_loss": 2.5, "val_rmse_nm": 1.6, "is_best": true},
                {"epoch": 2, "train_loss": 1.0, "val_loss": 1.2, "val_rmse_nm": 1.1, "is_best": true},
                {"epoch": 3, "train_loss": 0.5, "val_loss": null, "val_rmse_nm": null, "is_best": false}
            ]
        })
        .to_string(),
    )
    .unwrap();
    let figs = dir.join("figs");
    let json = dir.join("eval.json");
    let run = |extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
            .arg("eval")
            .arg("--dataset")
            .arg(&csv)
            .arg("--cv")
            .arg(&cv_json)
            .arg("--scv")
            .arg(&scv_json)
            .arg("--pinn")
            .arg(&pinn)
            .arg("--train-report")
            .arg(&report)
            .arg("--out")
            .arg(&figs)
            .arg("--json")
            .arg(&json)
            .args(extra)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "frictl eval failed: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        println!("{}", String::from_utf8_lossy(&out.stdout));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        v
    };
    let v = run(&[]);
    assert_eq!(v["format"], "frictionless-eval-v1");
    for name in ["none", "cv", "scv", "pinn"] {
        for key in [
            "rmse_all",
            "rmse_sliding",
            "rmse_stick",
            "rmse_true_all",
            "rmse_true_sliding",
            "rmse_true_stick",
            "n_samples",
        ] {
            assert!(
                v["models"][name][key].is_number(),
                "models.{name}.{key} = {}",
                v["models"][name][key]
            );
        }
    }
    let n_all = v["models"]["pinn"]["n_samples"].as_u64().unwrap();
    assert_eq!(n_all as usize, ds.len() - 3 * (H - 1));
    let pinn_rmse = v["models"]["pinn"]["rmse_all"].as_f64().unwrap();
    assert!((pinn_rmse - SIGMA).abs() < 0.15 * SIGMA);
    for f in [
        "heldout_friction_vs_velocity.png",
        "heldout_timeseries.png",
        "heldout_hysteresis.png",
        "training_curves.png",
    ] {
        assert_eq!(png_size(&figs.join(f)), (1200, 800), "{f}");
    }

    // --test-only: the report's test split holds chunk 2 of this dataset (dataset 1 of the report,
    // matched by path; its dataset 0 is another file).
    let v = run(&["--test-only"]);
    assert_eq!(v["test_only"], true);
    let n_test = v["models"]["scv"]["n_samples"].as_u64().unwrap();
    assert_eq!(n_test as usize, CHUNK_ROWS - (H - 1));
    std::fs::remove_dir_all(&dir).ok();
}

/// Writes a dataset sidecar naming the three chunks as runs `slow`, `mid`, `fast` (the chunks' peak
/// |ṡ| and |s| grow with the chunk id).
fn write_run_sidecar(csv: &Path, ds: &Dataset) {
    let runs: Vec<serde_json::Value> = ["slow", "mid", "fast"]
        .iter()
        .enumerate()
        .map(|(c, n)| serde_json::json!({"name": n, "source": format!("{n}.csv"), "chunks": [c]}))
        .collect();
    let side = serde_json::json!({
        "format": "frictionless-dataset-v1", "producer": "test", "input_log": "x", "input_sha256": "00",
        "joint": "", "gear_ratio_signed": R, "kt_nm_per_a": 0.05, "fs_hz": 1000.0, "settings": {},
        "dynamics": "", "delta_theta_offset_motor_rad": 0.0, "samples": ds.len(),
        "valid_samples": ds.len(), "chunks": 3, "short_chunks": 0, "columns": [], "runs": runs
    });
    std::fs::write(csv.with_extension("json"), side.to_string()).unwrap();
}

#[test]
fn cli_holds_out_runs_and_reports_per_run_per_band_and_extrapolation() {
    let dir = crate::util::scratch("eval_runs");
    std::fs::create_dir_all(&dir).unwrap();
    let p = scv();
    let ds = dataset(&|v, _| p.torque_nm(v), 5, DeltaThetaOffset::Run);
    let csv = dir.join("three.csv");
    ds.write_csv(&csv).unwrap();
    write_run_sidecar(&csv, &ds);
    let scv_json = dir.join("scv.json");
    std::fs::write(
        &scv_json,
        serde_json::json!({"model": "Scv", "params": p}).to_string(),
    )
    .unwrap();
    let json = dir.join("eval.json");
    let run = |extra: &[&str]| -> (bool, String, serde_json::Value) {
        let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
            .arg("eval")
            .arg("--scv")
            .arg(&scv_json)
            .arg("--json")
            .arg(&json)
            .args(extra)
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let v = if out.status.success() {
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap()
        } else {
            serde_json::Value::Null
        };
        (out.status.success(), text, v)
    };
    let csv_s = csv.to_str().unwrap();
    let n = |v: &serde_json::Value| v.as_u64().unwrap() as usize;

    // Hold out the slowest and the fastest run: trained on mid only, slow lies inside its range of s
    // and ṡ, fast has rows beyond it.
    let (ok, text, v) = run(&[
        "--dataset",
        csv_s,
        "--test-run",
        "slow",
        "--test-run",
        "fast",
    ]);
    assert!(ok, "{text}");
    assert!(
        text.contains("Per run") && text.contains("Per |sdot| band"),
        "{text}"
    );
    assert_eq!(
        n(&v["models"]["scv"]["n_samples"]),
        2 * CHUNK_ROWS,
        "only the held-out runs"
    );
    let runs = v["per_run"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(
        (&runs[0]["run"], &runs[1]["run"]),
        (&"slow".into(), &"fast".into())
    );
    assert_eq!(n(&runs[1]["evaluated"]), CHUNK_ROWS);
    assert_eq!(n(&runs[0]["extrapolated"]), 0);
    // The range is mid's: count the fast rows outside it independently.
    let mid = CHUNK_ROWS..2 * CHUNK_ROWS;
    let (mut s_lo, mut s_hi, mut v_lo, mut v_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for k in mid {
        s_lo = s_lo.min(ds.s_rad[k]);
        s_hi = s_hi.max(ds.s_rad[k]);
        v_lo = v_lo.min(ds.sdot_rad_s[k]);
        v_hi = v_hi.max(ds.sdot_rad_s[k]);
    }
    let outside = (2 * CHUNK_ROWS..3 * CHUNK_ROWS)
        .filter(|&k| {
            !(s_lo..=s_hi).contains(&ds.s_rad[k]) || !(v_lo..=v_hi).contains(&ds.sdot_rad_s[k])
        })
        .count();
    assert!(outside > 0);
    assert_eq!(n(&runs[1]["extrapolated"]), outside);
    assert_eq!(v["training_range"]["source"], "datasets");
    assert_eq!(
        v["training_range"]["range"]["sdot_rad_s"],
        serde_json::json!([v_lo, v_hi])
    );
    assert!(runs[0]["models"]["scv"]["rmse_inside"].is_number());
    assert!(runs[0]["models"]["scv"]["rmse_outside"].is_null());
    let scv_fast = &runs[1]["models"]["scv"];
    for key in ["rmse_all", "rmse_outside", "rmse_true_outside"] {
        assert!(scv_fast[key].is_number(), "{key} = {}", scv_fast[key]);
    }
    // The true SCV: label noise only, vs the truth exactly 0 (also outside the range).
    assert!((scv_fast["rmse_all"].as_f64().unwrap() - SIGMA).abs() < 0.15 * SIGMA);
    assert!(scv_fast["rmse_true_outside"].as_f64().unwrap() < 1e-9);
    // none is the friction itself: far worse.
    assert!(runs[1]["models"]["none"]["rmse_all"].as_f64().unwrap() > 5.0 * SIGMA);
    // Bands partition the rows; edges are the defaults.
    let bands = v["per_band"].as_array().unwrap();
    assert_eq!(bands.len(), 5);
    assert_eq!(
        bands.iter().map(|b| n(&b["n"])).sum::<usize>(),
        2 * CHUNK_ROWS
    );
    assert!(bands[4]["hi_rad_s"].is_null());
    let band_rows = (0..CHUNK_ROWS)
        .chain(2 * CHUNK_ROWS..3 * CHUNK_ROWS)
        .filter(|&k| (0.1..0.5).contains(&ds.sdot_rad_s[k].abs()))
        .count();
    assert_eq!(n(&bands[2]["n"]), band_rows);

    // Hold out the middle run: slow + fast span it, nothing is extrapolated; custom band edges.
    let (ok, text, v) = run(&[
        "--dataset",
        csv_s,
        "--test-run",
        "mid",
        "--band-edges",
        "0,0.5",
    ]);
    assert!(ok, "{text}");
    assert_eq!(v["per_run"][0]["run"], "mid");
    assert_eq!(n(&v["per_run"][0]["extrapolated"]), 0);
    assert!(v["per_run"][0]["models"]["scv"]["rmse_outside"].is_null());
    assert_eq!(v["per_band"].as_array().unwrap().len(), 2);
    assert_eq!(v["band_edges_rad_s"], serde_json::json!([0.0, 0.5]));

    // Everything scored without held-out runs: one entry per run, no extrapolation flags.
    let (ok, text, v) = run(&["--test-dataset", csv_s]);
    assert!(ok, "{text}");
    assert_eq!(v["per_run"].as_array().unwrap().len(), 3);
    assert!(v["training_range"].is_null());
    assert!(v["per_run"][2]["extrapolated"].is_null());

    // An unknown run name is an error naming it and the runs there are.
    let (ok, text, _) = run(&["--dataset", csv_s, "--test-run", "medium"]);
    assert!(!ok);
    assert!(
        text.contains("medium") && text.contains("slow, mid, fast"),
        "{text}"
    );
    let (ok, text, _) = run(&["--dataset", csv_s, "--band-edges", "0.5,0.1"]);
    assert!(!ok && text.contains("--band-edges"), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `frictl fit lugre` on a dataset labelled with LuGre's steady state (SCV with sign()) writes a
/// `Lugre` fit (static part from the SCV fit, σ0 and σ1 as given) and its `[[joint]]` snippet, and
/// `frictl eval --lugre` scores it far better than no model.
#[test]
fn fit_lugre_then_eval_scores_it() {
    let dir = crate::util::scratch("eval_lugre");
    std::fs::create_dir_all(&dir).unwrap();
    let curve = ScvParams {
        ka: f64::INFINITY,
        ..scv()
    };
    let ds = dataset(&|v, _| curve.torque_nm(v), 5, DeltaThetaOffset::Run);
    let csv = dir.join("ds.csv");
    ds.write_csv(&csv).unwrap();
    let fit_json = dir.join("lugre.json");
    let fit_toml = dir.join("lugre.toml");
    let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .args(["fit", "lugre"])
        .arg(&csv)
        .args(["--sigma0", "1e5", "--sigma1", "0.5", "--json"])
        .arg(&fit_json)
        .arg("--toml")
        .arg(&fit_toml)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "frictl fit lugre: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let f: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&fit_json).unwrap()).unwrap();
    assert_eq!(f["model"], "Lugre");
    assert_eq!(f["daemon_friction_model"], "lugre");
    let p = &f["params"];
    let kc = p["kc"].as_f64().unwrap();
    assert!(kc > 0.0, "kc {kc}");
    assert_eq!(p["sigma0"], 1e5);
    assert_eq!(p["sigma1"], 0.5);
    assert_eq!(
        f["param_names"],
        serde_json::json!(["kc", "kv", "ks", "vs", "alpha", "sigma0", "sigma1"])
    );
    let toml = std::fs::read_to_string(&fit_toml).unwrap();
    assert!(
        toml.contains("friction_model = \"lugre\"") && toml.contains("sigma0 = "),
        "{toml}"
    );

    let json = dir.join("eval.json");
    let out = Command::new(env!("CARGO_BIN_EXE_frictl"))
        .arg("eval")
        .arg("--dataset")
        .arg(&csv)
        .arg("--lugre")
        .arg(&fit_json)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "frictl eval --lugre: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rmse = |m: &str| v["models"][m]["rmse_all"].as_f64().unwrap();
    assert!(
        rmse("lugre") < 0.5 * rmse("none"),
        "lugre {} none {}",
        rmse("lugre"),
        rmse("none")
    );
    std::fs::remove_dir_all(&dir).ok();
}

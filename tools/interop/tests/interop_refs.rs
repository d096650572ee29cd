//! The ONNX importer against ONNX Runtime outputs written by `tests/python/gen_onnx_refs.py`
//! (random MLPs in every supported graph form, and the ergoCub model on extra random inputs).
//!
//! Needs `FRICTIONLESS_REFS` (set by `tests/run.sh`): the tests are `#[ignore]`d, so a plain
//! `cargo test` reports them as ignored; `tests/run.sh` runs them with `--include-ignored`, and there an
//! unset variable or a missing file fails.

use frictionless_test_support::onnx as interop_common;

use std::path::PathBuf;

use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::StorageDtype;
use frictionless_interop::onnx;
use interop_common::*;

/// The expected reference files (must match the generator's list).
const MODELS: [&str; 6] = [
    "gemm_t1_diagnorm_h1",
    "gemm_t0_nonorm_h2",
    "matmul_add_diagnorm_h3",
    "gemm_t1_alpha_beta_floatdata_h2",
    "gemm_t0_alpha_floatdata_h1",
    "matmul_add_subdiv_h2",
];

fn refs_dir() -> PathBuf {
    let dir = std::env::var_os("FRICTIONLESS_REFS").expect(
        "FRICTIONLESS_REFS is unset: run bash tests/run.sh (it writes the ONNX Runtime references)",
    );
    PathBuf::from(dir).join("onnx")
}

fn load_json(p: &std::path::Path) -> serde_json::Value {
    let b = std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e} (run tests/run.sh)", p.display()));
    serde_json::from_slice(&b).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Checks every input/output pair through all kernel paths and the reference forward pass.
fn check(mlp: &frictionless::mlp::MlpWeights, json: &serde_json::Value, what: &str) -> usize {
    let inputs = json["inputs"].as_array().unwrap();
    let outputs = json["outputs"].as_array().unwrap();
    assert_eq!(inputs.len(), outputs.len());
    assert!(!inputs.is_empty(), "{what}: no cases");
    for path in KernelPath::available() {
        let mut k = Mlp::new(mlp, StorageDtype::F32)
            .unwrap()
            .with_path(path)
            .unwrap();
        for (j, (x, y)) in inputs.iter().zip(outputs).enumerate() {
            let x = f32s(x);
            let want = y.as_f64().unwrap() as f32;
            assert_close(
                k.forward(&x),
                want,
                1e-5,
                1e-6,
                &format!("{what} case {j} kernel {path}"),
            );
            assert_close(
                mlp.forward_reference(&x)[0],
                want,
                1e-5,
                1e-6,
                &format!("{what} case {j} reference"),
            );
        }
    }
    inputs.len()
}

#[test]
#[ignore = "needs FRICTIONLESS_REFS: bash tests/run.sh"]
fn random_onnx_models_match_onnx_runtime() {
    let dir = refs_dir();
    let mut total = 0;
    for name in MODELS {
        let json = load_json(&dir.join(format!("{name}.json")));
        let imp =
            onnx::import_file(&dir.join(format!("{name}.onnx"))).unwrap_or_else(|e| panic!("{e}"));
        let mut sizes = vec![json["n_inputs"].as_u64().unwrap() as usize];
        sizes.extend(
            json["hidden"]
                .as_array()
                .unwrap()
                .iter()
                .map(|h| h.as_u64().unwrap() as usize),
        );
        sizes.push(1);
        assert_eq!(imp.mlp.sizes(), sizes, "{name}");
        assert_eq!(imp.normalisation_found, !json["norm"].is_null(), "{name}");
        total += check(&imp.mlp, &json, name);
    }
    eprintln!("checked {total} ORT cases over {} models", MODELS.len());
}

#[test]
#[ignore = "needs FRICTIONLESS_REFS: bash tests/run.sh"]
fn ergocub_model_matches_onnx_runtime_on_extra_inputs() {
    let dir = refs_dir();
    let json = load_json(&dir.join("ergocub_extra.json"));
    let imp = onnx::import_file(&anchor_onnx()).unwrap();
    assert!(check(&imp.mlp, &json, "ergocub_extra") >= 32);
}

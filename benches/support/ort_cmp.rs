//! ONNX Runtime vs the hand-written kernel, single sample, one thread (feature `ort-bench`).
//!
//! Not a correctness test of the importer: it loads the same weights into both from the bench fixtures
//! written by `benches/make_paper_onnx.py` (a raw f32 file next to each ONNX model), checks that the two
//! agree, and times one call of each (ORT timing includes wrapping the input and reading the output).
//! Environment (set by `benches/ort_compare.sh`): `ORT_DYLIB_PATH` = libonnxruntime.so from the PyPI
//! wheel, `FRICTIONLESS_ORT_DIR` = directory with `paper.onnx`, `paper.raw`, `ergocub.raw`.

use super::{ERGOCUB, N_INPUTS, PAPER, print_stats, stats};
use frictionless::kernel::Mlp;
use frictionless::mlp::{Activation, DenseLayer, MlpWeights, Normalisation, StorageDtype};
use ort::session::Session;
use ort::session::builder::GraphOptimizationLevel;
use ort::value::TensorRef;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn err(msg: impl Into<String>) -> ort::Error {
    ort::Error::new(msg)
}

/// Reads the raw fixture format described in `benches/make_paper_onnx.py`.
fn read_raw(path: &Path) -> ort::Result<MlpWeights> {
    let bytes = std::fs::read(path).map_err(|e| err(format!("{}: {e}", path.display())))?;
    let bad = |what: &str| err(format!("{}: {what}", path.display()));
    if bytes.len() < 12 || &bytes[..8] != b"FLRAW1\0\0" {
        return Err(bad("bad magic"));
    }
    let mut off = 8;
    let u32_at = |off: &mut usize| -> ort::Result<u32> {
        let v = bytes.get(*off..*off + 4).ok_or_else(|| bad("truncated"))?;
        *off += 4;
        Ok(u32::from_le_bytes([v[0], v[1], v[2], v[3]]))
    };
    let n = u32_at(&mut off)? as usize;
    let sizes: Vec<usize> = (0..n)
        .map(|_| u32_at(&mut off).map(|v| v as usize))
        .collect::<ort::Result<_>>()?;
    let f32s = |count: usize, off: &mut usize| -> ort::Result<Vec<f32>> {
        let v = bytes
            .get(*off..*off + 4 * count)
            .ok_or_else(|| bad("truncated"))?;
        *off += 4 * count;
        Ok(v.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    };
    let mean = f32s(sizes[0], &mut off)?;
    let scale = f32s(sizes[0], &mut off)?;
    let mut layers = Vec::new();
    for k in 0..n - 1 {
        let (ni, no) = (sizes[k], sizes[k + 1]);
        let weight = f32s(ni * no, &mut off)?;
        let bias = f32s(no, &mut off)?;
        let activation = if k + 2 == n {
            Activation::Identity
        } else {
            Activation::Relu
        };
        layers.push(DenseLayer {
            n_in: ni,
            n_out: no,
            weight,
            bias,
            activation,
        });
    }
    if off != bytes.len() {
        return Err(bad("trailing bytes"));
    }
    let w = MlpWeights {
        norm: Normalisation { mean, scale },
        layers,
    };
    w.validate().map_err(|e| bad(&e.to_string()))?;
    Ok(w)
}

/// Runs the comparison; prints "skipped" if the environment is not prepared.
pub(crate) fn run(full: bool) {
    let (Some(lib), Some(dir)) = (
        std::env::var_os("ORT_DYLIB_PATH"),
        std::env::var_os("FRICTIONLESS_ORT_DIR"),
    ) else {
        println!(
            "ort: skipped: run benches/ort_compare.sh (needs ORT_DYLIB_PATH and FRICTIONLESS_ORT_DIR)"
        );
        return;
    };
    if let Err(e) = compare(Path::new(&lib), &PathBuf::from(dir), full) {
        println!("ort: failed: {e}");
    }
}

fn compare(lib: &Path, dir: &Path, full: bool) -> ort::Result<()> {
    let env = ort::init_from(lib)
        .map_err(|e| err(format!("loading {}: {e}", lib.display())))?
        .build()?;
    let anchor = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/ergocub/blf_jtc_ergoCubSN002_l_ankle_roll_pinn_2024-06.onnx");
    let models = [
        (
            "paper",
            PAPER,
            dir.join("paper.onnx"),
            dir.join("paper.raw"),
        ),
        ("ergocub", ERGOCUB, anchor, dir.join("ergocub.raw")),
    ];
    let iters = if full { 20_000 } else { 10 };
    for (name, sizes, onnx_path, raw_path) in models {
        let w = read_raw(&raw_path)?;
        if w.sizes() != sizes {
            return Err(err(format!(
                "{}: sizes {:?}, expected {sizes:?}",
                raw_path.display(),
                w.sizes()
            )));
        }
        let mut ours = Mlp::new(&w, StorageDtype::F32).map_err(|e| err(e.to_string()))?;
        let mut session = Session::builder(&env)?
            .with_optimization_level(GraphOptimizationLevel::Level3)?
            .with_intra_threads(1)?
            .with_inter_threads(1)?
            .commit_from_file(&onnx_path)?;
        let n = w.n_inputs();
        let mut rng = ChaCha8Rng::seed_from_u64(43);
        let xs: Vec<Vec<f32>> = (0..N_INPUTS)
            .map(|_| {
                w.norm
                    .mean
                    .iter()
                    .zip(&w.norm.scale)
                    .map(|(&m, &s)| m + s * rng.random_range(-2.0f32..2.0))
                    .collect()
            })
            .collect();
        let mut ort_once = |x: &[f32]| -> ort::Result<f32> {
            let out = session
                .run(ort::inputs!["input" => TensorRef::from_array_view(([1usize, n], x))?])?;
            let (_, y) = out["output"].try_extract_tensor::<f32>()?;
            y.first().copied().ok_or_else(|| err("empty output"))
        };
        // Agreement (same weights in both).
        let mut worst_abs = 0f32;
        let mut worst_rel = 0f32;
        for x in &xs {
            let (a, b) = (ort_once(x)?, ours.forward(x));
            worst_abs = worst_abs.max((a - b).abs());
            worst_rel = worst_rel.max((a - b).abs() / a.abs().max(1e-3));
        }
        println!(
            "ort/{name}: {} vs ORT over {N_INPUTS} inputs: max |diff| {worst_abs:.2e}, max rel {worst_rel:.2e}",
            ours.path()
        );
        // Timing, interleaved warm-up then one loop each.
        for (i, x) in xs.iter().cycle().take(2000.min(iters * 10)).enumerate() {
            black_box(ort_once(x)?);
            black_box(ours.forward(&xs[i % N_INPUTS]));
        }
        let mut t_ort = Vec::with_capacity(iters);
        for x in xs.iter().cycle().take(iters) {
            let t0 = Instant::now();
            black_box(ort_once(black_box(x))?);
            t_ort.push(t0.elapsed().as_nanos() as u64);
        }
        let mut t_ours = Vec::with_capacity(iters);
        for x in xs.iter().cycle().take(iters) {
            let t0 = Instant::now();
            black_box(ours.forward(black_box(x)));
            t_ours.push(t0.elapsed().as_nanos() as u64);
        }
        let (so, sk) = (stats(t_ort), stats(t_ours));
        print_stats(&format!("ort/{name}/onnxruntime"), &so);
        print_stats(&format!("ort/{name}/kernel-{}-f32", ours.path()), &sk);
        println!(
            "ort/{name}: ratio ORT/ours  p50 {:.1}×  p99 {:.1}×",
            so.p50 / sk.p50,
            so.p99 / sk.p99
        );
    }
    Ok(())
}

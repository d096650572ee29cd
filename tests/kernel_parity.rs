//! Parity of the inference kernel ([`frictionless::kernel::Mlp`]) with the f64 reference forward pass
//! ([`MlpWeights::forward_reference`]) on every kernel path the machine supports × every storage dtype,
//! on random networks of many shapes. (That `forward` never allocates is proven in `alloc_free.rs`,
//! the binary with the counting allocator.)
//!
//! Tolerance: `|kernel − reference| ≤ 1e-5 · max(|reference|, m)` where `m = |b| + Σ|w_i·a_i|` is the
//! magnitude of the output neuron's terms (computed in f64 here). Using `m` keeps the bound meaningful
//! when an output happens to cancel to ~0; it is the natural scale of f32 summation error.
//! For f16/bf16 storage the reference runs on the weights rounded to that dtype (rounded here with the
//! `half` crate, independently of the kernel), then the same 1e-5 bound applies. For int8 the reference
//! runs on the per-channel dequantised weights ([`frictionless::kernel::storage_rounded`]); every path
//! that keeps f32 activations ("weight-only": avx512, avx2fma, portable) meets the same 1e-5 bound;
//! the VNNI path also quantises every hidden layer's input after the first to u8 (step max/255) and
//! is held to [`VNNI_BOUND`] relative to the same scale.

use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::{Activation, MlpWeights, Normalisation, StorageDtype};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

// ---------------------------------------------------------------------------------------------------
// Random networks.

/// A random MLP with He-uniform weights (activations neither die nor explode with depth), small
/// positive-leaning biases and a non-trivial normalisation; its seed is the next draw of `rng`.
fn random_net(rng: &mut ChaCha8Rng, sizes: &[usize]) -> MlpWeights {
    let spec = RandomMlpSpec {
        sizes: sizes.to_vec(),
        weights: WeightInit::HeUniform,
        bias: -0.1..0.3,
        norm: NormInit::Uniform {
            mean: -2.0..2.0,
            scale: 0.25..4.0,
        },
    };
    seeded_mlp(&spec, rng.random()).expect("random net is valid")
}

/// Raw inputs around the normalisation mean (normalised values roughly in ±2).
fn random_input(rng: &mut ChaCha8Rng, w: &MlpWeights) -> Vec<f32> {
    w.norm
        .mean
        .iter()
        .zip(&w.norm.scale)
        .map(|(&m, &s)| m + s * rng.random_range(-2.0f32..2.0))
        .collect()
}

/// Weights rounded to the storage dtype (what a reduced-precision kernel computes with).
fn rounded(w: &MlpWeights, dtype: StorageDtype) -> MlpWeights {
    let mut r = w.clone();
    for l in &mut r.layers {
        for v in &mut l.weight {
            *v = match dtype {
                StorageDtype::F32 => *v,
                StorageDtype::F16 => half::f16::from_f32(*v).to_f32(),
                StorageDtype::Bf16 => half::bf16::from_f32(*v).to_f32(),
                StorageDtype::Int8 | StorageDtype::Int16 => {
                    return frictionless::kernel::storage_rounded(w, dtype);
                }
            };
        }
    }
    r
}

/// Relative bound of the int8 VNNI path (u8 activations) against the dequantised-weight reference.
const VNNI_BOUND: f64 = 5e-3;

/// Relative bound of the int16 paths (15-bit activations) against the dequantised-weight reference.
const INT16_BOUND: f64 = 1e-3;

/// The bound for a path × dtype (see the module doc).
fn bound(path: KernelPath, dtype: StorageDtype) -> f64 {
    if path == KernelPath::Avx512Vnni && dtype == StorageDtype::Int8 {
        VNNI_BOUND
    } else if dtype == StorageDtype::Int16 {
        INT16_BOUND
    } else {
        1e-5
    }
}

/// f64 forward pass returning (output, magnitude of the output neuron's terms).
fn forward_f64_with_magnitude(w: &MlpWeights, x: &[f32]) -> (f64, f64) {
    let mut a: Vec<f64> = x
        .iter()
        .zip(w.norm.mean.iter().zip(&w.norm.scale))
        .map(|(&x, (&m, &s))| (x as f64 - m as f64) / s as f64)
        .collect();
    let last = w.layers.len() - 1;
    for (k, l) in w.layers.iter().enumerate() {
        let mut y = vec![0f64; l.n_out];
        let mut mag = 0f64;
        for (o, yo) in y.iter_mut().enumerate() {
            let mut acc = l.bias[o] as f64;
            mag = (l.bias[o] as f64).abs();
            for (wv, xi) in l.weight[o * l.n_in..(o + 1) * l.n_in].iter().zip(&a) {
                acc += *wv as f64 * xi;
                mag += (*wv as f64 * xi).abs();
            }
            *yo = if l.activation == Activation::Relu {
                acc.max(0.0)
            } else {
                acc
            };
        }
        if k == last {
            return (y[0], mag);
        }
        a = y;
    }
    unreachable!("a validated net has at least one layer")
}

const DTYPES: [StorageDtype; 5] = StorageDtype::ALL;

/// Checks every available path × dtype on `w` with `n_inputs` random inputs; returns the worst
/// relative error seen.
fn check_net(rng: &mut ChaCha8Rng, w: &MlpWeights, n_inputs: usize) -> f64 {
    let paths = KernelPath::available();
    let xs: Vec<Vec<f32>> = (0..n_inputs).map(|_| random_input(rng, w)).collect();
    let mut worst = 0f64;
    for dtype in DTYPES {
        let wr = rounded(w, dtype);
        let refs: Vec<(f32, f64)> = xs
            .iter()
            .map(|x| {
                let (y64, mag) = forward_f64_with_magnitude(&wr, x);
                let y = wr.forward_reference(x)[0];
                // Our f64 pass and the crate's reference must agree (guards the magnitude helper).
                assert!(
                    (y as f64 - y64).abs() <= 1e-6 * mag.max(1e-30),
                    "reference helpers disagree"
                );
                (y, mag)
            })
            .collect();
        for &path in &paths {
            let mut m = Mlp::new(w, dtype).unwrap().with_path(path).unwrap();
            assert_eq!(m.path(), path);
            assert_eq!(m.dtype(), dtype);
            assert_eq!(m.n_inputs(), w.n_inputs());
            for (x, &(y_ref, mag)) in xs.iter().zip(&refs) {
                let y = m.forward(x);
                let scale = (y_ref.abs() as f64).max(mag).max(1e-30);
                let rel = (y as f64 - y_ref as f64).abs() / scale;
                assert!(
                    rel <= bound(path, dtype),
                    "sizes {:?} {dtype:?} {path}: kernel {y} vs reference {y_ref} (rel {rel:.3e}, magnitude {mag:.3e})",
                    w.sizes()
                );
                if bound(path, dtype) == 1e-5 {
                    worst = worst.max(rel);
                } else if dtype == StorageDtype::Int16 {
                    worst_int16().set(worst_int16().get().max(rel));
                } else {
                    worst_vnni().set(worst_vnni().get().max(rel));
                }
            }
        }
    }
    worst
}

/// Worst relative error of the VNNI int8 path seen by this thread (reported, not part of `worst`).
fn worst_vnni() -> &'static std::thread::LocalKey<std::cell::Cell<f64>> {
    thread_local!(static W: std::cell::Cell<f64> = const { std::cell::Cell::new(0.0) });
    &W
}

/// Worst relative error of the int16 paths seen by this thread (reported, not part of `worst`).
fn worst_int16() -> &'static std::thread::LocalKey<std::cell::Cell<f64>> {
    thread_local!(static W: std::cell::Cell<f64> = const { std::cell::Cell::new(0.0) });
    &W
}

/// int16 is exact integer arithmetic plus the same f32 steps in the same order on every path: the
/// outputs are bit-identical across paths (odd widths, inputs not a multiple of a chunk, up to the
/// deepest nets), and the error against the dequantised-weight f64 reference stays within
/// `INT16_BOUND`.
#[test]
fn int16_paths_are_bit_identical() {
    let mut rng = ChaCha8Rng::seed_from_u64(16);
    let paths = KernelPath::available();
    let shapes: [&[usize]; 6] = [
        &[1, 1, 1],
        &[3, 17, 1],
        &[40, 268, 215, 1],
        &[50, 450, 210, 280, 1],
        &[33, 15, 31, 47, 9, 1],
        &[17, 16, 1],
    ];
    let mut worst = 0f64;
    for sizes in shapes {
        let w = random_net(&mut rng, sizes);
        let wr = frictionless::kernel::storage_rounded(&w, StorageDtype::Int16);
        let mut nets: Vec<Mlp> = paths
            .iter()
            .map(|&p| {
                Mlp::new(&w, StorageDtype::Int16)
                    .unwrap()
                    .with_path(p)
                    .unwrap()
            })
            .collect();
        for _ in 0..50 {
            let x = random_input(&mut rng, &w);
            let y: Vec<f32> = nets.iter_mut().map(|m| m.forward(&x)).collect();
            for (p, v) in paths.iter().zip(&y) {
                assert_eq!(
                    v.to_bits(),
                    y[0].to_bits(),
                    "{sizes:?}: {p} gives {v}, {} gives {}",
                    paths[0],
                    y[0]
                );
            }
            let (y_ref, mag) = forward_f64_with_magnitude(&wr, &x);
            let rel = (f64::from(y[0]) - y_ref).abs() / y_ref.abs().max(mag).max(1e-30);
            assert!(
                rel <= INT16_BOUND,
                "{sizes:?}: {} vs {y_ref} ({rel:.2e})",
                y[0]
            );
            worst = worst.max(rel);
        }
    }
    eprintln!(
        "int16 on {} paths, bit-identical; worst relative error {worst:.2e}",
        paths.len()
    );
}

#[test]
fn portable_path_always_available_and_forcing_works() {
    assert!(KernelPath::Portable.is_available());
    assert!(KernelPath::available().contains(&KernelPath::detect()));
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let w = random_net(&mut rng, &[4, 8, 1]);
    for p in KernelPath::ALL {
        let r = Mlp::new(&w, StorageDtype::F32).unwrap().with_path(p);
        assert_eq!(r.is_ok(), p.is_available(), "{p}");
    }
    // A freshly built kernel runs on the detected path.
    assert_eq!(
        Mlp::new(&w, StorageDtype::F32).unwrap().path(),
        KernelPath::detect()
    );
    eprintln!("kernel paths on this CPU: {:?}", KernelPath::available());
}

#[test]
fn fixed_shapes_all_paths_all_dtypes() {
    let shapes: &[&[usize]] = &[
        &[1, 1],
        &[17, 1],
        &[1, 1, 1],
        &[1, 16, 1],
        &[1, 17, 1],
        &[3, 15, 33, 1],
        &[40, 268, 215, 1],
        &[50, 450, 210, 280, 1],
        &[7, 33, 15, 129, 65, 1],
        &[1024, 1, 1024, 1],
        &[1024, 1024, 1],
        &[5, 1024, 1000, 1024, 999, 1],
        &[64, 128, 144, 136, 120, 1],
        // Small students: one to three output blocks, whose inputs the AVX2 f32 path splits over
        // several accumulator sets (input counts below, at and off a multiple of the split).
        &[90, 32, 32, 32, 1],
        &[90, 16, 16, 1],
        &[3, 16, 1],
        &[4, 32, 1],
        &[31, 48, 7, 1],
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for s in shapes {
        let w = random_net(&mut rng, s);
        let worst = check_net(&mut rng, &w, 3);
        eprintln!("{s:?}: worst relative error {worst:.2e}");
    }
    eprintln!(
        "fixed shapes, int8 VNNI: worst relative error {:.2e}",
        worst_vnni().with(|c| c.get())
    );
}

#[test]
fn random_shapes_all_paths_all_dtypes() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut worst = 0f64;
    for _ in 0..40 {
        let n_hidden = rng.random_range(0..=4usize);
        let dim = |rng: &mut ChaCha8Rng| {
            // Mostly small (odd multiples of nothing in particular), sometimes up to the limit.
            if rng.random_bool(0.8) {
                rng.random_range(1..=96usize)
            } else {
                rng.random_range(97..=1024usize)
            }
        };
        let mut sizes = vec![dim(&mut rng)];
        for _ in 0..n_hidden {
            sizes.push(dim(&mut rng));
        }
        sizes.push(1);
        let w = random_net(&mut rng, &sizes);
        worst = worst.max(check_net(&mut rng, &w, 2));
    }
    eprintln!("random shapes: worst relative error {worst:.2e}");
}

/// The real ergoCub model's shape (50→450→210→280→1) with its real folded normalisation and its real
/// raw input vectors from the reference I/O JSON, random weights. (Full parity with the real weights is
/// the ONNX importer's test.)
#[test]
fn ergocub_shape_with_real_normalisation_and_inputs() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/ergocub/blf_jtc_ergoCubSN002_l_ankle_roll_pinn_2024-06.reference_io.json"
    );
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let j: serde_json::Value = serde_json::from_str(&text).expect("anchor JSON parses");
    let norm = &j["normalisation_folded_in_first_Gemm"];
    let vecf = |v: &serde_json::Value| -> Vec<f32> {
        v.as_array()
            .expect("array")
            .iter()
            .map(|e| e.as_f64().expect("number") as f32)
            .collect()
    };
    let mean = vecf(&norm["mean"]);
    let scale = vecf(&norm["scale_iqr"]);
    assert_eq!(mean.len(), 50);
    assert_eq!(scale.len(), 50);
    let inputs: Vec<Vec<f32>> = j["cases"]
        .as_array()
        .expect("cases")
        .iter()
        .map(|c| vecf(&c["input"]))
        .collect();
    assert_eq!(inputs.len(), 9);

    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let mut w = random_net(&mut rng, &[50, 450, 210, 280, 1]);
    w.norm = Normalisation { mean, scale };
    w.validate().unwrap();
    for dtype in DTYPES {
        let wr = rounded(&w, dtype);
        for path in KernelPath::available() {
            let mut m = Mlp::new(&w, dtype).unwrap().with_path(path).unwrap();
            for x in &inputs {
                let (y_ref, mag) = forward_f64_with_magnitude(&wr, x);
                let y = m.forward(x) as f64;
                assert!(
                    (y - y_ref).abs() <= bound(path, dtype) * y_ref.abs().max(mag),
                    "{dtype:?} {path}: {y} vs {y_ref} (magnitude {mag})"
                );
            }
        }
    }
}

/// Reduced precision against the *unrounded* f32 model: the stated accuracy bounds (relative to the output
/// neuron's magnitude) are 2e-3 for f16 (11-bit significand), 2e-2 for bf16 (8-bit significand) and
/// 2e-2 for int8 (per-channel scales; on the detected path, which is VNNI where the CPU has it).
#[test]
fn reduced_precision_error_vs_f32_is_bounded() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let w = random_net(&mut rng, &[40, 268, 215, 1]);
    for (dtype, bound) in [
        (StorageDtype::F16, 2e-3),
        (StorageDtype::Bf16, 2e-2),
        (StorageDtype::Int8, 2e-2),
        (StorageDtype::Int16, 5e-4),
    ] {
        let mut m = Mlp::new(&w, dtype).unwrap();
        let mut worst = 0f64;
        for _ in 0..20 {
            let x = random_input(&mut rng, &w);
            let (y_ref, mag) = forward_f64_with_magnitude(&w, &x);
            let rel = (m.forward(&x) as f64 - y_ref).abs() / y_ref.abs().max(mag);
            worst = worst.max(rel);
        }
        eprintln!("{dtype:?} vs f32 model: worst relative error {worst:.2e}");
        assert!(worst <= bound, "{dtype:?}: {worst:.3e} > {bound}");
        assert!(
            worst > 0.0,
            "{dtype:?}: rounding had no effect at all, the weights were not rounded"
        );
    }
}

#[test]
fn wrong_input_length_returns_nan_on_every_path() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let w = random_net(&mut rng, &[6, 20, 1]);
    for dtype in DTYPES {
        for path in KernelPath::available() {
            let mut m = Mlp::new(&w, dtype).unwrap().with_path(path).unwrap();
            assert!(m.forward(&[]).is_nan());
            assert!(m.forward(&[0.0; 5]).is_nan());
            assert!(m.forward(&[0.0; 7]).is_nan());
            assert!(m.forward(&[0.0; 6]).is_finite());
        }
    }
}

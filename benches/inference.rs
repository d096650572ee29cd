//! Inference benchmarks of [`frictionless::kernel::Mlp`] (results in docs/performance.md; no timing
//! asserts).
//!
//! - `hot/<model>/<path>/<dtype>` (criterion): back-to-back single inferences, weights hot in cache, for
//!   the paper-size PINN 40→268→215→1 and the ergoCub-size 50→450→210→280→1, every available kernel path
//!   × f32/f16/bf16/int8 (int8 on `avx512vnni` = u8 activations × int8 weights with `vpdpbusd`; on the
//!   other paths int8 weights decoded to f32). `hot/layer1`, `hot/layer2`: the paper net's two hidden
//!   layers as separate nets (40→268→1, and 4→268→215→1 whose 268→215 layer dominates) on the
//!   detected path, for the per-layer cost. `hot/floor/<dtype>`: only reading the paper net's weight
//!   bytes in that dtype (32-byte loads summed, no arithmetic on them), back to back: the memory floor
//!   under a hot single inference (138–278 KB stream from L2, which is larger than L1).
//! - `paced/...` (custom loop): one inference per tick with a 0.9 ms sleep between ticks (1 kHz), p50/p99.
//! - `tick32/...` (custom loop): 32 distinct paper-size nets once each per 1 kHz tick, every dtype, on
//!   one thread and split over two threads (a spinning worker), p50/p99; plus the accuracy cost of
//!   f16/bf16/int8 (int8 weight-only and int8 VNNI) as max |error| in Nm against f32 on nets scaled to
//!   output a few Nm.
//! - `ort/...` (feature `ort-bench`, custom loop): ONNX Runtime vs this kernel, single sample, one thread;
//!   run through `benches/ort_compare.sh`.
//!
//! Filters: `cargo bench --bench inference -- <regex>`; the custom loops honour a plain substring or a
//! `^prefix` filter. Under `cargo test` (no `--bench`) every part runs once as a smoke test.

use criterion::Criterion;
use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::{MlpWeights, StorageDtype};
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

const PAPER: &[usize] = &[40, 268, 215, 1];
const ERGOCUB: &[usize] = &[50, 450, 210, 280, 1];
/// The shape of the default demo's distilled students (H 30 × 3 features, three 32-wide layers).
const STUDENT: &[usize] = &[90, 32, 32, 32, 1];
/// A two-layer student of the same inputs.
const STUDENT2: &[usize] = &[90, 32, 32, 1];
const DTYPES: [StorageDtype; 5] = StorageDtype::ALL;
const N_INPUTS: usize = 64;

fn dtype_name(d: StorageDtype) -> &'static str {
    d.name()
}

/// A random MLP (He-uniform weights, small biases, non-trivial normalisation) from the library's seeded
/// builder; the seed is drawn from the bench's own stream so each call gives a different net.
fn random_net(rng: &mut ChaCha8Rng, sizes: &[usize]) -> MlpWeights {
    let spec = RandomMlpSpec {
        weights: WeightInit::HeUniform,
        bias: -0.1..0.3,
        norm: NormInit::Uniform {
            mean: -0.5..0.5,
            scale: 0.5..2.0,
        },
        ..RandomMlpSpec::new(sizes)
    };
    seeded_mlp(&spec, rng.random()).expect("valid bench net")
}

fn random_inputs(rng: &mut ChaCha8Rng, w: &MlpWeights, n: usize) -> Vec<Vec<f32>> {
    (0..n)
        .map(|_| {
            w.norm
                .mean
                .iter()
                .zip(&w.norm.scale)
                .map(|(&m, &s)| m + s * rng.random_range(-2.0f32..2.0))
                .collect()
        })
        .collect()
}

/// Rescales the output layer so the outputs over `xs` have zero mean and a standard deviation of
/// `std_nm` (a realistic friction torque range of a few Nm).
fn scale_output(w: &mut MlpWeights, xs: &[Vec<f32>], std_nm: f64) {
    let ys: Vec<f64> = xs
        .iter()
        .map(|x| w.forward_reference(x)[0] as f64)
        .collect();
    let mean = ys.iter().sum::<f64>() / ys.len() as f64;
    let sd = (ys.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / ys.len() as f64)
        .sqrt()
        .max(1e-12);
    let k = std_nm / sd;
    let last = w.layers.last_mut().expect("non-empty net");
    for v in &mut last.weight {
        *v = (*v as f64 * k) as f32;
    }
    last.bias[0] = ((last.bias[0] as f64 - mean) * k) as f32;
}

/// Percentiles of a sample of durations in ns.
struct Stats {
    p50: f64,
    p99: f64,
    max: f64,
}

fn stats(mut ns: Vec<u64>) -> Stats {
    ns.sort_unstable();
    let pick = |q: f64| ns[((ns.len() - 1) as f64 * q).round() as usize] as f64;
    Stats {
        p50: pick(0.5),
        p99: pick(0.99),
        max: *ns.last().unwrap_or(&0) as f64,
    }
}

fn print_stats(name: &str, s: &Stats) {
    println!(
        "{name:<44} p50 {:>9.2} µs   p99 {:>9.2} µs   max {:>9.2} µs",
        s.p50 / 1e3,
        s.p99 / 1e3,
        s.max / 1e3
    );
}

/// Run configuration from the command line.
struct Cli {
    /// Full benchmark mode (`cargo bench`); otherwise a quick smoke run (`cargo test`).
    bench: bool,
    filter: Option<String>,
}

impl Cli {
    fn parse() -> Self {
        let args: Vec<String> = std::env::args().skip(1).collect();
        let bench = args.iter().any(|a| a == "--bench") && !args.iter().any(|a| a == "--test");
        let filter = args.iter().find(|a| !a.starts_with('-')).cloned();
        Self { bench, filter }
    }
    /// Whether a custom loop named `name` is selected by the filter.
    fn wants(&self, name: &str) -> bool {
        match &self.filter {
            None => true,
            Some(f) => match f.strip_prefix('^') {
                Some(prefix) => name.starts_with(prefix),
                None => name.contains(f.as_str()),
            },
        }
    }
    fn ticks(&self) -> usize {
        if self.bench { 2000 } else { 5 }
    }
}

// ---------------------------------------------------------------------------------------------------

fn hot(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(40);
    for (model, sizes) in [
        ("paper", PAPER),
        ("ergocub", ERGOCUB),
        ("student", STUDENT),
        ("student2", STUDENT2),
    ] {
        let w = random_net(&mut rng, sizes);
        let xs = random_inputs(&mut rng, &w, N_INPUTS);
        let mut g = c.benchmark_group(format!("hot/{model}"));
        for path in KernelPath::available() {
            for dtype in DTYPES {
                let mut m = Mlp::new(&w, dtype)
                    .expect("valid net")
                    .with_path(path)
                    .expect("available path");
                let mut i = 0usize;
                g.bench_function(format!("{path}/{}", dtype_name(dtype)), |b| {
                    b.iter(|| {
                        i = (i + 1) % N_INPUTS;
                        m.forward(black_box(&xs[i]))
                    })
                });
            }
        }
        g.finish();
    }
    // Per-layer cost on the detected path: the paper net's first hidden layer (40→268, with a 268→1
    // output) and its second behind a tiny first layer (4→268→215→1, so that on the VNNI path the
    // 268→215 layer runs as a later layer, with u8 activations, as in the paper net).
    let path = KernelPath::detect();
    for (model, sizes) in [
        ("layer1", &[40, 268, 1][..]),
        ("layer2", &[4, 268, 215, 1][..]),
    ] {
        let w = random_net(&mut rng, sizes);
        let xs = random_inputs(&mut rng, &w, N_INPUTS);
        let mut g = c.benchmark_group(format!("hot/{model}"));
        for dtype in DTYPES {
            let mut m = Mlp::new(&w, dtype).expect("valid net");
            let mut i = 0usize;
            g.bench_function(format!("{path}/{}", dtype_name(dtype)), |b| {
                b.iter(|| {
                    i = (i + 1) % N_INPUTS;
                    m.forward(black_box(&xs[i]))
                })
            });
        }
        g.finish();
    }
    // The memory floor: the paper net's weight bytes in each dtype, only read.
    let w = random_net(&mut rng, PAPER);
    let mut g = c.benchmark_group("hot/floor");
    for dtype in DTYPES {
        let bytes = Mlp::new(&w, dtype).expect("valid net").weight_bytes();
        let lines = vec![Line([1; 64]); bytes.div_ceil(64)];
        g.bench_function(format!("{}/{}KB", dtype_name(dtype), bytes / 1000), |b| {
            b.iter(|| stream(black_box(&lines)))
        });
    }
    g.finish();
}

/// 64 bytes, 64-byte aligned: the streamed buffer of `hot/floor`.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Line([u8; 64]);

/// Reads every byte of `lines` once (sums them as u64 words in four independent chains) and returns the
/// sum: the cost of streaming those bytes from wherever they are, with no arithmetic on them to speak
/// of. Hand-written for the floor measurement only; on x86-64 with AVX2, 32-byte loads as the kernels do.
fn stream(lines: &[Line]) -> u64 {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is present.
        return unsafe { stream_avx2(lines) };
    }
    let mut acc = [0u64; 4];
    for l in lines {
        for (k, w) in l.0.chunks_exact(8).enumerate() {
            acc[k % 4] = acc[k % 4].wrapping_add(u64::from_ne_bytes(w.try_into().unwrap()));
        }
    }
    acc.iter().fold(0, |a, &b| a.wrapping_add(b))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn stream_avx2(lines: &[Line]) -> u64 {
    use std::arch::x86_64::*;
    let (mut a, mut b) = (_mm256_setzero_si256(), _mm256_setzero_si256());
    for l in lines {
        // SAFETY: each line is 64 readable, 64-byte aligned bytes.
        unsafe {
            let p = l.0.as_ptr().cast::<__m256i>();
            a = _mm256_add_epi64(a, _mm256_load_si256(p));
            b = _mm256_add_epi64(b, _mm256_load_si256(p.add(1)));
        }
    }
    let mut out = [0u64; 4];
    // SAFETY: 32 writable bytes.
    unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), _mm256_add_epi64(a, b)) };
    out.iter().fold(0, |x, &y| x.wrapping_add(y))
}

/// One inference per 1 kHz tick (0.9 ms sleep in between): the weights cool down between calls.
fn paced(cli: &Cli) {
    let mut rng = ChaCha8Rng::seed_from_u64(41);
    for (model, sizes) in [("paper", PAPER), ("ergocub", ERGOCUB)] {
        let w = random_net(&mut rng, sizes);
        let xs = random_inputs(&mut rng, &w, N_INPUTS);
        for path in KernelPath::available() {
            for dtype in DTYPES {
                let name = format!("paced/{model}/{path}/{}", dtype_name(dtype));
                if !cli.wants(&name) {
                    continue;
                }
                let mut m = Mlp::new(&w, dtype)
                    .expect("valid net")
                    .with_path(path)
                    .expect("available path");
                let mut ns = Vec::with_capacity(cli.ticks());
                for t in 0..cli.ticks() {
                    std::thread::sleep(Duration::from_micros(900));
                    let t0 = Instant::now();
                    black_box(m.forward(black_box(&xs[t % N_INPUTS])));
                    ns.push(t0.elapsed().as_nanos() as u64);
                }
                print_stats(&name, &stats(ns));
            }
        }
    }
}

/// 32 distinct nets, scaled to a realistic output range.
fn tick32_nets(rng: &mut ChaCha8Rng) -> (Vec<MlpWeights>, Vec<Vec<Vec<f32>>>) {
    let mut nets = Vec::new();
    let mut inputs = Vec::new();
    for _ in 0..32 {
        let mut w = random_net(rng, PAPER);
        let xs = random_inputs(rng, &w, N_INPUTS);
        scale_output(&mut w, &xs, 2.0);
        nets.push(w);
        inputs.push(xs);
    }
    (nets, inputs)
}

/// 32 distinct paper-size nets per tick: accuracy of f16/bf16/int8, then paced tick timing on 1 and 2
/// threads.
fn tick32(cli: &Cli) {
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let (nets, inputs) = tick32_nets(&mut rng);
    let path = KernelPath::detect();

    if cli.wants("tick32/accuracy") {
        let mut f32_m: Vec<Mlp> = nets
            .iter()
            .map(|w| Mlp::new(w, StorageDtype::F32).expect("valid"))
            .collect();
        let mut range = (f32::INFINITY, f32::NEG_INFINITY);
        for (m, xs) in f32_m.iter_mut().zip(&inputs) {
            for x in xs {
                let y = m.forward(x);
                range = (range.0.min(y), range.1.max(y));
            }
        }
        println!(
            "tick32/accuracy: f32 outputs span [{:.3}, {:.3}] Nm over 32 nets × {N_INPUTS} inputs",
            range.0, range.1
        );
        let variants = [
            (StorageDtype::F16, path),
            (StorageDtype::Bf16, path),
            (StorageDtype::Int8, KernelPath::Portable),
            (StorageDtype::Int8, path),
            (StorageDtype::Int16, path),
        ];
        for (dtype, p) in variants {
            let mut worst = 0f32;
            let mut sum = 0f64;
            let mut n = 0usize;
            for ((w, xs), mf) in nets.iter().zip(&inputs).zip(&mut f32_m) {
                let mut m = Mlp::new(w, dtype)
                    .expect("valid")
                    .with_path(p)
                    .expect("available");
                for x in xs {
                    let e = (m.forward(x) - mf.forward(x)).abs();
                    worst = worst.max(e);
                    sum += e as f64;
                    n += 1;
                }
            }
            println!(
                "tick32/accuracy/{:<5} ({p}) vs f32: max |error| {:.2e} Nm, mean |error| {:.2e} Nm",
                dtype_name(dtype),
                worst,
                sum / n as f64
            );
        }
    }

    for dtype in DTYPES {
        let name = format!("tick32/1thread/{path}/{}", dtype_name(dtype));
        if cli.wants(&name) {
            let mut ms: Vec<Mlp> = nets
                .iter()
                .map(|w| Mlp::new(w, dtype).expect("valid"))
                .collect();
            let mut ns = Vec::with_capacity(cli.ticks());
            for t in 0..cli.ticks() {
                std::thread::sleep(Duration::from_micros(900));
                let t0 = Instant::now();
                for (m, xs) in ms.iter_mut().zip(&inputs) {
                    black_box(m.forward(black_box(&xs[t % N_INPUTS])));
                }
                ns.push(t0.elapsed().as_nanos() as u64);
            }
            print_stats(&name, &stats(ns));
        }
        let name = format!("tick32/2threads/{path}/{}", dtype_name(dtype));
        if cli.wants(&name) {
            print_stats(
                &name,
                &tick32_two_threads(&nets, &inputs, dtype, cli.ticks()),
            );
        }
    }
}

/// The tick split over two threads: the main thread runs nets 0..16, a spinning worker runs 16..32.
/// The tick time is from the main thread's release of the worker to both halves being done.
/// (A spinning worker is what a daemon with two isolated cores would do; here it burns the second core
/// while the main thread sleeps.)
fn tick32_two_threads(
    nets: &[MlpWeights],
    inputs: &[Vec<Vec<f32>>],
    dtype: StorageDtype,
    ticks: usize,
) -> Stats {
    let mut mine: Vec<Mlp> = nets[..16]
        .iter()
        .map(|w| Mlp::new(w, dtype).expect("valid"))
        .collect();
    let theirs: Vec<Mlp> = nets[16..]
        .iter()
        .map(|w| Mlp::new(w, dtype).expect("valid"))
        .collect();
    let go = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let worker = {
        let (go, done, stop) = (go.clone(), done.clone(), stop.clone());
        let inputs: Vec<Vec<Vec<f32>>> = inputs[16..].to_vec();
        let mut theirs = theirs;
        std::thread::spawn(move || {
            let mut seen = 0u64;
            loop {
                let t = go.load(Ordering::Acquire);
                if t == seen {
                    if stop.load(Ordering::Relaxed) {
                        return;
                    }
                    std::hint::spin_loop();
                    continue;
                }
                seen = t;
                for (m, xs) in theirs.iter_mut().zip(&inputs) {
                    black_box(m.forward(black_box(&xs[t as usize % N_INPUTS])));
                }
                done.store(t, Ordering::Release);
            }
        })
    };
    let mut ns = Vec::with_capacity(ticks);
    for t in 1..=ticks as u64 {
        std::thread::sleep(Duration::from_micros(900));
        let t0 = Instant::now();
        go.store(t, Ordering::Release);
        for (m, xs) in mine.iter_mut().zip(&inputs[..16]) {
            black_box(m.forward(black_box(&xs[t as usize % N_INPUTS])));
        }
        while done.load(Ordering::Acquire) != t {
            std::hint::spin_loop();
        }
        ns.push(t0.elapsed().as_nanos() as u64);
    }
    stop.store(true, Ordering::Relaxed);
    let _ = worker.join();
    stats(ns)
}

#[cfg(feature = "ort-bench")]
#[path = "support/ort_cmp.rs"]
mod ort_cmp;

fn main() {
    let cli = Cli::parse();
    let mut c = Criterion::default()
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .configure_from_args();
    hot(&mut c); // criterion applies the filter itself
    c.final_summary();
    if cli.wants("paced/") {
        paced(&cli);
    }
    if cli.wants("tick32/") {
        tick32(&cli);
    }
    #[cfg(feature = "ort-bench")]
    if cli.wants("ort/") {
        ort_cmp::run(cli.bench);
    }
}

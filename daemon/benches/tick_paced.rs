//! The RT tick's compute time at 1 kHz pacing, as frictiond runs it: per tick, sleep to the next
//! 1 ms boundary (with `prefetch = "lead"` waking earlier to prefetch, as the RT loop does), then
//! the compute step on one thread ([`frictiond::rt::compute`]) or two ([`frictiond::rt::Crew`], the
//! helper thread of `[loop] rt_threads = 2`, joints split by [`Params::split_threads`]); the time
//! from the wake to the end of the compute step is recorded, as frictiond's `compute` histogram.
//! Between ticks the rest of the machine runs and evicts the weights from the caches — the cost a
//! hot loop (`--bench tick`) does not see.
//!
//! Prints markdown:
//! 0. the accuracy gate on the 32 tick networks: max |Δτ̂_F| of each reduced dtype against f32 on
//!    every kernel path, and how many networks stay within 0.01 Nm;
//! 1. where the time goes: bytes of weights per tick per dtype; one paper-size network hot vs right
//!    after a full-cache eviction (a 64 MiB write), and the same for its first layer alone (the
//!    second layer by difference); a 32-joint tick hot, after eviction, and after eviction followed
//!    by a prefetch walk of every joint (and how long that walk takes);
//! 2. the paced compute time for 1, 15 and 32 joints × the networks ([`MODELS`]: the paper-size
//!    ones, and 32 distinct small students distilled from them in the setup) × the storage dtypes
//!    ([`DTYPES`], one array) × 1 and 2 RT threads × prefetch off / after / lead, next to the hot
//!    single-model floor and the hot back-to-back tick: p50 / p99 / max over the **steal-free**
//!    ticks (those during which the bench thread's own run-queue delay, `/proc/thread-self/schedstat`,
//!    did not grow — no other task of this machine ran on its CPU meanwhile — and its CPU time grew
//!    with the wall clock to within [`OFF_CPU_SLACK_NS`] — the hypervisor did not take its vCPU
//!    away: with steal-time accounting a thread's CPU time excludes steal), their fraction, the
//!    ticks the host stole from, and p50 / p99 / p99.9 / max over all ticks.
//!
//! No asserts, no criterion for the paced part. Run: `cargo bench -p frictiond --bench tick_paced`
//! (about 8 minutes: 90 cells × `TICKS` ticks at 1 kHz; `TICK_PACED_TICKS=n` changes the count,
//! `TICK_PACED_DTYPES=int16,f16` measures only those dtypes, `TICK_PACED_JOINTS=32`,
//! `TICK_PACED_THREADS=2`, `TICK_PACED_PREFETCH=lead` and `TICK_PACED_MODELS=student` only those
//! cells, and
//! `TICK_PACED_REPEAT=k` runs each paced cell k times, `TICK_PACED_LEAD_US=u` prefetches u µs
//! before the deadline instead of frictiond's default 200, `TICK_PACED_ONLY_PACED=1` skips parts 0
//! and 1, `TICK_PACED_STUDENT=FILE` makes the students 32 distinct copies of that model).
//! Each paced cell also reports the time the hypervisor stole from this VM's vCPUs meanwhile
//! (`steal` in `/proc/stat`, all CPUs, ms, 10 ms granularity): the per-tick test above sees only
//! the bench thread's vCPU while it computes, so steal there means the host was busy during the
//! cell (its caches and memory shared) even when every steal-free tick kept its vCPU.
//! Runs as an ordinary thread (SCHED_OTHER) unless `TICK_PACED_PRIORITY=p` asks for SCHED_FIFO `p`
//! for the bench thread and the helper (as frictiond's `[loop] priority`); timer slack 1 ns as in
//! frictiond. On a shared machine the numbers include its load — note `uptime` next to them.

use std::hint::black_box;

use frictiond::config::Prefetch;
use frictiond::params::Params;
use frictiond::rt::{
    Crew, CrewPlan, Freshness, HELPER_RELEASE_GRACE_NS, Inputs, ThreadRt, compute, main_half,
    prefetch_after_publish, prefetch_joints, sleep_to_deadline,
};
use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::StorageDtype;
use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
use frictionless_shm_types::{MAX_JOINTS, MotorCurrentCommand, monotonic_ns};

#[path = "support/tick_params.rs"]
mod tick_params;
use frictionless::weights::ModelFile;
use tick_params::{H, inputs, paper_file, paper_weights, params, params_with, pinn_of};

/// Storage dtypes measured (one array: a new `.fwt` dtype is one more entry).
const DTYPES: [(&str, StorageDtype); 5] = [
    ("f32", StorageDtype::F32),
    ("f16", StorageDtype::F16),
    ("bf16", StorageDtype::Bf16),
    ("int16", StorageDtype::Int16),
    ("int8", StorageDtype::Int8),
];

/// [`DTYPES`], or those named in `TICK_PACED_DTYPES` (comma-separated, e.g. `int16,f16`).
fn dtypes() -> Vec<(&'static str, StorageDtype)> {
    only("TICK_PACED_DTYPES", &DTYPES, |d| d.0.to_owned())
}
/// Joint counts: one joint, ergoCub legs + torso, a whole humanoid.
const JOINTS: [usize; 3] = [1, 15, 32];

/// The items of `all` whose name is listed in the environment variable `var` (comma-separated), or
/// all of them when it is unset.
fn only<T: Copy>(var: &str, all: &[T], name: impl Fn(&T) -> String) -> Vec<T> {
    match std::env::var(var) {
        Ok(list) => all
            .iter()
            .filter(|x| list.split(',').any(|w| w.trim() == name(x)))
            .copied()
            .collect(),
        Err(_) => all.to_vec(),
    }
}

/// Time stolen by the hypervisor from all of this VM's CPUs so far [ms] (`/proc/stat` `cpu` line,
/// 8th value, in USER_HZ = 100 ticks/s); 0 where it is not reported.
fn steal_ms() -> u64 {
    std::fs::read_to_string("/proc/stat")
        .ok()
        .and_then(|t| {
            let line = t.lines().next()?.to_owned();
            line.split_whitespace().nth(8)?.parse::<u64>().ok()
        })
        .map_or(0, |ticks| ticks * 10)
}
/// The calling thread's run-queue delay so far [ns]: the second field of
/// `/proc/thread-self/schedstat` (time spent runnable but waiting for a CPU). Read from an open file
/// with `pread` into a stack buffer (no allocation).
struct RunDelay(Option<std::fs::File>);

impl RunDelay {
    /// Opens the calling thread's `schedstat` (read on this thread only); `None` inside when the
    /// kernel has no schedstats.
    fn open() -> Self {
        Self(std::fs::File::open("/proc/thread-self/schedstat").ok())
    }

    /// The delay so far [ns], 0 without schedstats.
    fn ns(&self) -> u64 {
        use std::os::unix::fs::FileExt;
        let Some(f) = &self.0 else { return 0 };
        let mut buf = [0u8; 96];
        let n = f.read_at(&mut buf, 0).unwrap_or(0);
        std::str::from_utf8(&buf[..n])
            .ok()
            .and_then(|t| t.split_whitespace().nth(1)?.parse().ok())
            .unwrap_or(0)
    }
}

/// Which networks the paced joints run (`TICK_PACED_MODELS=paper,student` selects).
#[derive(Clone, Copy, PartialEq)]
enum Models {
    /// The paper-size `[Δθ ×20, ṡ ×20]` → 268 → 215 → 1 networks (seeded random weights).
    Paper,
    /// Small students distilled (probe-only) from the paper-size networks, [`STUDENT_WIDTHS`].
    Student,
}
const MODELS: [(&str, Models); 2] = [("paper", Models::Paper), ("student", Models::Student)];
/// Hidden widths of the students: joint k gets `STUDENT_WIDTHS[k % 3]` (distinct seeds and teachers
/// make every student's weights distinct).
const STUDENT_WIDTHS: [[usize; 2]; 3] = [[32, 32], [24, 32], [32, 24]];

/// The 32 students: [`distilled_students`], or with `TICK_PACED_STUDENT=FILE` 32 copies of that model (e.g. a student `frictl demo
/// --distill` wrote), joint k's weights scaled by 1 + k·1e-4 so that no two are equal: the cost of
/// 32 joints running a real student's shape and dtype.
fn students() -> Vec<ModelFile> {
    if let Ok(path) = std::env::var("TICK_PACED_STUDENT") {
        let file = frictionless::weights::read_file(std::path::Path::new(&path))
            .unwrap_or_else(|e| panic!("TICK_PACED_STUDENT={path}: {e}"));
        return (0..32u16)
            .map(|k| {
                let mut f = file.clone();
                let g = 1.0 + f32::from(k) * 1e-4;
                for l in &mut f.mlp.layers {
                    l.weight.iter_mut().chain(&mut l.bias).for_each(|w| *w *= g);
                }
                f
            })
            .collect();
    }
    distilled_students()
}

/// 32 students, joint k distilled without data from joint k's paper-size network (probes inside
/// mean ± 3·scale of its identity normalisation), f32; the gate bound is loose (the teachers are
/// random functions: the students are here for their cost, not their accuracy).
fn distilled_students() -> Vec<ModelFile> {
    use frictionless_train::TrainConfig;
    use frictionless_train::distill::{ProbeDistillConfig, distill_probes};
    (0..32u64)
        .map(|k| {
            let teacher = paper_file(k, StorageDtype::F32);
            let cfg = ProbeDistillConfig {
                train: TrainConfig {
                    hidden: STUDENT_WIDTHS[k as usize % 3].to_vec(),
                    dropout: 0.0,
                    lambda: 0.0,
                    lr: 2e-3,
                    batch_size: 256,
                    epochs: 5,
                    seed: k,
                    threads: 1,
                    patience: None,
                    abort_loss: None,
                },
                dtype: StorageDtype::F32,
                probes: 4000,
                val_probes: 500,
                test_probes: 500,
                max_rmse_nm: f64::MAX,
                probe_kind: Default::default(),
                lr_final: None,
                init: Default::default(),
            };
            distill_probes(&teacher, [0; 32], &cfg, |_| {
                std::ops::ControlFlow::Continue(())
            })
            .expect("student distils")
            .model
        })
        .collect()
}

/// Prefetch policies (`[loop] prefetch`).
const PREFETCH: [(&str, Prefetch); 3] = [
    ("off", Prefetch::Off),
    ("after", Prefetch::After),
    ("lead", Prefetch::Lead),
];
/// The accuracy gate of a storage change: max |Δτ̂_F| against f32 [Nm].
const GATE_NM: f32 = 0.01;
/// Paced ticks per cell (≥ 5000).
const TICKS: usize = 5000;
/// Period [ns] (1 kHz).
const PERIOD_NS: u64 = 1_000_000;
/// `prefetch_lead_us` used for "lead" [ns] (frictiond's default); `TICK_PACED_LEAD_US` changes it.
const LEAD_NS: u64 = 200_000;

/// The lead of "lead" prefetching [ns]: `TICK_PACED_LEAD_US` if set, else [`LEAD_NS`].
fn lead_ns() -> u64 {
    std::env::var("TICK_PACED_LEAD_US")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
        .map_or(LEAD_NS, |us| us.saturating_mul(1000))
}
/// Bytes written to evict every cache level (L3 here is 32 MiB).
const EVICT_BYTES: usize = 64 << 20;

const FRESH: Freshness = Freshness {
    state_stale: false,
    request_stale: false,
};

fn quantile(sorted: &[u64], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let k = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[k]
}

fn us(ns: u64) -> String {
    format!("{:.1}", ns as f64 / 1000.0)
}

/// Writes one byte per cache line of `buf`: every cache level then holds `buf`, not the weights.
fn evict(buf: &mut [u8]) {
    for k in (0..buf.len()).step_by(64) {
        buf[k] = buf[k].wrapping_add(1);
    }
    black_box(&buf);
}

fn paper_net(sizes: &[usize], seed: u64, dtype: StorageDtype) -> Mlp {
    let spec = RandomMlpSpec {
        weights: WeightInit::HeUniform,
        norm: NormInit::Identity,
        ..RandomMlpSpec::new(sizes)
    };
    Mlp::new(&seeded_mlp(&spec, seed).expect("valid bench net"), dtype).expect("valid layout")
}

/// Median time of one forward [ns], hot (back to back) and right after an eviction.
fn forward_hot_cold(m: &mut Mlp, evict_buf: &mut [u8]) -> (u64, u64) {
    let x: Vec<f32> = (0..m.n_inputs()).map(|i| (i as f32 * 0.1).sin()).collect();
    let mut hot = Vec::with_capacity(2000);
    for _ in 0..2000 {
        let t = monotonic_ns();
        black_box(m.forward(black_box(&x)));
        hot.push(monotonic_ns() - t);
    }
    let mut cold = Vec::with_capacity(100);
    for _ in 0..100 {
        evict(evict_buf);
        let t = monotonic_ns();
        black_box(m.forward(black_box(&x)));
        cold.push(monotonic_ns() - t);
    }
    hot.sort_unstable();
    cold.sort_unstable();
    (quantile(&hot, 0.5), quantile(&cold, 0.5))
}

/// Runs `p` past warm-up so every tick runs every network.
fn warm(p: &mut Params, inp: &Inputs) -> (MotorCurrentCommand, [f64; MAX_JOINTS], u64) {
    let mut cmd = MotorCurrentCommand::zeroed();
    let mut tau_f = [0.0; MAX_JOINTS];
    let mut prev = 0u64;
    for _ in 0..H + 1 {
        compute(p, inp, FRESH, &mut prev, &mut cmd, &mut tau_f);
    }
    (cmd, tau_f, prev)
}

fn where_the_time_goes(evict_buf: &mut [u8]) {
    println!("### Where the time goes (one paper-size network; a 32-joint tick)\n");
    println!(
        "| dtype | weights / net [KiB] | 32 nets [MiB] | net hot [µs] | net cold [µs] | layer 1 hot / cold [µs] | layer 2 (diff.) hot / cold [µs] | 32-joint tick hot [µs] | 32-joint tick cold [µs] | prefetch walk, cold [µs] | tick after walk [µs] |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, dtype) in dtypes() {
        let mut full = paper_net(&[40, 268, 215, 1], 1, dtype);
        let mut first = paper_net(&[40, 268, 1], 1, dtype);
        let (full_hot, full_cold) = forward_hot_cold(&mut full, evict_buf);
        let (l1_hot, l1_cold) = forward_hot_cold(&mut first, evict_buf);
        let mut p = params(32, Some(dtype), 1);
        let bytes: usize = p.joints.iter().map(|j| j.model.weight_bytes()).sum();
        let mut inp = inputs(32);
        let (mut cmd, mut tau_f, mut prev) = warm(&mut p, &inp);
        let (mut hot, mut cold, mut walk, mut warmed) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for k in 0..600u64 {
            inp.states.value.sdot_rad_s[31] = 0.4 + (k % 100) as f64 * 1e-3;
            // 0: after a tick of the same nets (hot but for what did not fit); 1: after an
            // eviction; 2: after an eviction and a prefetch walk of every joint.
            let case = k % 3;
            if case >= 1 {
                evict(evict_buf);
            }
            if case == 2 {
                let t = monotonic_ns();
                prefetch_joints(&p.joints);
                walk.push(monotonic_ns() - t);
            }
            let t = monotonic_ns();
            compute(&mut p, &inp, FRESH, &mut prev, &mut cmd, &mut tau_f);
            let dt = monotonic_ns() - t;
            [&mut hot, &mut cold, &mut warmed][case as usize].push(dt);
        }
        for v in [&mut hot, &mut cold, &mut walk, &mut warmed] {
            v.sort_unstable();
        }
        println!(
            "| {name} | {:.0} | {:.2} | {} | {} | {} / {} | {} / {} | {} | {} | {} | {} |",
            full.weight_bytes() as f64 / 1024.0,
            bytes as f64 / (1 << 20) as f64,
            us(full_hot),
            us(full_cold),
            us(l1_hot),
            us(l1_cold),
            us(full_hot.saturating_sub(l1_hot)),
            us(full_cold.saturating_sub(l1_cold)),
            us(quantile(&hot, 0.5)),
            us(quantile(&cold, 0.5)),
            us(quantile(&walk, 0.5)),
            us(quantile(&warmed, 0.5)),
        );
    }
    println!();
}

/// A tick whose wall time exceeds the bench thread's CPU time over it by more than this [ns] lost
/// its vCPU to the host (the two `clock_gettime` calls around it make the CPU time slightly larger
/// than the wall time otherwise).
const OFF_CPU_SLACK_NS: u64 = 2_000;

/// The calling thread's CPU time [ns] (`CLOCK_THREAD_CPUTIME_ID`; it excludes the time the
/// hypervisor stole when the guest kernel accounts steal time). 0 if the clock is unavailable.
fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec.
    if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } != 0 {
        return 0;
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// What [`paced`] measured.
struct PacedRun {
    /// Compute time from wake of every tick [ns], sorted.
    all: Vec<u64>,
    /// Of the ticks during which the bench thread's run-queue delay did not grow and the host took
    /// nothing from its vCPU, sorted.
    steal_free: Vec<u64>,
    /// Ticks during which the host took the bench thread's vCPU away (wall − CPU time >
    /// [`OFF_CPU_SLACK_NS`]).
    host_stolen: usize,
    /// Helper late ticks.
    late: u64,
    /// Ticks whose helper half the bench thread ran itself.
    stolen: u64,
}

/// Paced ticks of `p` on one thread or with `crew`. Around each tick (outside the timed region) the
/// bench thread reads its own run-queue delay and CPU time: a tick during which the delay did not
/// grow and the CPU time kept up with the wall clock was neither preempted by another task of this
/// machine nor descheduled by the hypervisor ("steal-free"; on the bench thread only — with
/// `crew`, the helper's ticks are not checked).
fn paced(
    p: &mut Params,
    n: usize,
    mut crew: Option<&mut Crew>,
    plan: &CrewPlan,
    ticks: usize,
) -> PacedRun {
    let mut inp = inputs(n);
    let (mut cmd, mut tau_f, mut prev) = warm(p, &inp);
    let mut samples = Vec::with_capacity(ticks);
    let mut steal_free = Vec::with_capacity(ticks);
    let mut host_stolen = 0;
    let delay = RunDelay::open();
    let late0 = crew.as_ref().map_or(0, |c| c.late_ticks());
    let stolen0 = crew.as_ref().map_or(0, |c| c.stolen_ticks());
    for k in 0..ticks as u64 {
        inp.states.value.sdot_rad_s[n - 1] = 0.4 + (k % 100) as f64 * 1e-3;
        let deadline = (monotonic_ns() / PERIOD_NS + 1) * PERIOD_NS;
        sleep_to_deadline(deadline, plan.prefetch, plan.lead_ns, main_half(p));
        let delay0 = delay.ns();
        let cpu0 = thread_cpu_ns();
        let wake = monotonic_ns();
        match crew.as_deref_mut() {
            None => compute(p, &inp, FRESH, &mut prev, &mut cmd, &mut tau_f),
            Some(c) => {
                c.release(wake + plan.release_ns);
                c.compute(
                    p, &inp, FRESH, &mut prev, &mut cmd, &mut tau_f, wake, deadline,
                );
            }
        }
        let done = monotonic_ns();
        let cpu = thread_cpu_ns().saturating_sub(cpu0);
        let off_host = done - wake > cpu + OFF_CPU_SLACK_NS;
        host_stolen += usize::from(off_host);
        if delay.ns() == delay0 && !off_host {
            steal_free.push(done - wake);
        }
        black_box(&cmd);
        prefetch_after_publish(plan, main_half(p));
        samples.push(done - wake);
    }
    samples.sort_unstable();
    steal_free.sort_unstable();
    PacedRun {
        all: samples,
        steal_free,
        host_stolen,
        late: crew.as_ref().map_or(0, |c| c.late_ticks()) - late0,
        stolen: crew.as_ref().map_or(0, |c| c.stolen_ticks()) - stolen0,
    }
}

/// `TICK_PACED_PRIORITY=p`: run the bench thread and the helper SCHED_FIFO at `p`, as frictiond
/// with `[loop] priority = p` (needs CAP_SYS_NICE); `None` when unset or refused.
fn fifo_priority() -> Option<i32> {
    let prio: i32 = std::env::var("TICK_PACED_PRIORITY").ok()?.parse().ok()?;
    // SAFETY: zeroed sched_param with its priority set, for the calling thread.
    let ok = unsafe {
        let mut sp: libc::sched_param = std::mem::zeroed();
        sp.sched_priority = prio;
        libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &sp) == 0
    };
    if !ok {
        eprintln!("TICK_PACED_PRIORITY={prio}: SCHED_FIFO refused; running SCHED_OTHER");
    }
    ok.then_some(prio)
}

/// The accuracy gate `frictl convert` applies, on the 32 tick networks: per dtype, max |Δτ̂_F|
/// against the same network in f32 over `probes` random inputs inside mean ± 3·scale (what `convert`
/// probes for a file without a training range) on every kernel path this CPU has.
fn accuracy_gate(probes: usize) {
    println!(
        "### Accuracy gate on the 32 tick networks (max |Δτ̂_F| vs f32, {probes} probes in mean ± 3·scale per net, every kernel path; gate {GATE_NM} Nm)\n"
    );
    println!(
        "| dtype | max over nets [Nm] | worst net | nets within the gate | f32 outputs span [Nm] |"
    );
    println!("|---|---|---|---|---|");
    let nets: Vec<_> = (0..32).map(paper_weights).collect();
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f32 / (1u64 << 53) as f32
    };
    let xs: Vec<Vec<Vec<f32>>> = nets
        .iter()
        .map(|w| {
            (0..probes)
                .map(|_| {
                    w.norm
                        .mean
                        .iter()
                        .zip(&w.norm.scale)
                        .map(|(m, s)| m + s * (6.0 * uniform() - 3.0))
                        .collect()
                })
                .collect()
        })
        .collect();
    let reference: Vec<Vec<f32>> = nets
        .iter()
        .zip(&xs)
        .map(|(w, xs)| {
            let mut m = Mlp::new(w, StorageDtype::F32).expect("valid");
            xs.iter().map(|x| m.forward(x)).collect()
        })
        .collect();
    let span = reference
        .iter()
        .flatten()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &y| {
            (lo.min(y), hi.max(y))
        });
    for (name, dtype) in dtypes() {
        if dtype == StorageDtype::F32 {
            continue;
        }
        let mut per_net = Vec::with_capacity(nets.len());
        for ((w, xs), refs) in nets.iter().zip(&xs).zip(&reference) {
            let mut worst = 0f32;
            for path in KernelPath::available() {
                let mut m = Mlp::new(w, dtype)
                    .expect("valid")
                    .with_path(path)
                    .expect("available");
                for (x, y) in xs.iter().zip(refs) {
                    worst = worst.max((m.forward(x) - y).abs());
                }
            }
            per_net.push(worst);
        }
        let (arg, max) =
            per_net.iter().enumerate().fold(
                (0, 0f32),
                |(a, m), (k, &e)| if e > m { (k, e) } else { (a, m) },
            );
        let within = per_net.iter().filter(|&&e| e <= GATE_NM).count();
        println!(
            "| {name} | {max:.2e} | j{arg} | {within}/{} | [{:.2}, {:.2}] |",
            nets.len(),
            span.0,
            span.1
        );
    }
    println!();
}

fn main() {
    // `cargo bench` passes `--bench`; a test run (`cargo test --benches`) passes nothing: be quick.
    let full = std::env::args().any(|a| a == "--bench");
    let priority = fifo_priority();
    // SAFETY: no preconditions.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1, 0, 0, 0) };
    let ticks = std::env::var("TICK_PACED_TICKS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(if full { TICKS } else { 50 });
    let mut evict_buf = vec![0u8; if full { EVICT_BYTES } else { 1 << 20 }];
    let t0 = monotonic_ns();
    let paced_only = std::env::var_os("TICK_PACED_ONLY_PACED").is_some();
    if !paced_only {
        accuracy_gate(if full { 1000 } else { 20 });
    }
    if !paced_only {
        where_the_time_goes(&mut evict_buf);
    }

    println!(
        "### Paced at 1 kHz: compute time per tick, wake → commands ready [µs], {ticks} ticks per cell, {}\n",
        match priority {
            Some(p) => format!("SCHED_FIFO {p}"),
            None => "SCHED_OTHER".to_owned(),
        }
    );
    let repeat: usize = std::env::var("TICK_PACED_REPEAT")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let models = only("TICK_PACED_MODELS", &MODELS, |m| m.0.to_owned());
    let students = if models.iter().any(|m| m.1 == Models::Student) {
        let t = monotonic_ns();
        let s = students();
        let macs = |f: &ModelFile| f.mlp.macs();
        println!(
            "Students: {} made in {:.1} s, hidden {:?}, {}–{} MAC each (paper-size: {} MAC).\n",
            s.len(),
            (monotonic_ns() - t) as f64 / 1e9,
            s.iter()
                .map(|f| f.mlp.layers.iter().map(|l| l.n_out).collect::<Vec<_>>())
                .collect::<std::collections::BTreeSet<_>>(),
            s.iter().map(macs).min().unwrap_or(0),
            s.iter().map(macs).max().unwrap_or(0),
            macs(&paper_file(0, StorageDtype::F32)),
        );
        s
    } else {
        Vec::new()
    };
    println!(
        "| joints | nets | dtype | hot 1 net p50 | hot tick p50 | threads | prefetch | steal-free p50 | steal-free p99 | steal-free max | all p50 | all p99 | all p99.9 | all max | steal-free ticks | host-stolen ticks | late | stolen | steal [ms] |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for n in only("TICK_PACED_JOINTS", &JOINTS, |j| j.to_string()) {
        for &(mname, kind) in &models {
            for (name, dtype) in dtypes() {
                let make = |threads: u8| match kind {
                    Models::Paper => params(n, Some(dtype), threads),
                    Models::Student => params_with(n, threads, |k| pinn_of(&students[k], dtype)),
                };
                let mut net = match kind {
                    Models::Paper => paper_net(&[40, 268, 215, 1], 1, dtype),
                    Models::Student => Mlp::new(&students[0].mlp, dtype).expect("valid layout"),
                };
                let (net_hot, _) = forward_hot_cold(&mut net, &mut evict_buf[..0]);
                // Hot back-to-back tick of the same joints.
                let mut p = make(1);
                let mut inp = inputs(n);
                let (mut cmd, mut tau_f, mut prev) = warm(&mut p, &inp);
                let mut hot = Vec::with_capacity(1000);
                for k in 0..1000u64 {
                    inp.states.value.sdot_rad_s[n - 1] = 0.4 + (k % 100) as f64 * 1e-3;
                    let t = monotonic_ns();
                    compute(&mut p, &inp, FRESH, &mut prev, &mut cmd, &mut tau_f);
                    hot.push(monotonic_ns() - t);
                }
                hot.sort_unstable();
                for threads in only("TICK_PACED_THREADS", &[1u8, 2], |t| t.to_string()) {
                    for (pname, prefetch) in only("TICK_PACED_PREFETCH", &PREFETCH, |p| p.0.into())
                    {
                        for _ in 0..repeat {
                            let mut p = make(threads);
                            let plan = CrewPlan {
                                period_ns: PERIOD_NS,
                                budget_ns: PERIOD_NS / 4 * 3,
                                release_ns: HELPER_RELEASE_GRACE_NS,
                                prefetch,
                                lead_ns: lead_ns(),
                                lockstep: false,
                            };
                            let steal0 = steal_ms();
                            let r = if threads == 2 {
                                let rt = ThreadRt {
                                    priority,
                                    ..ThreadRt::default()
                                };
                                let (mut crew, _, _) =
                                    Crew::spawn(plan, rt).expect("helper thread");
                                let r = paced(&mut p, n, Some(&mut crew), &plan, ticks);
                                crew.stop();
                                r
                            } else {
                                paced(&mut p, n, None, &plan, ticks)
                            };
                            let (s, f) = (&r.all, &r.steal_free);
                            println!(
                                "| {n} | {mname} | {name} | {} | {} | {threads} | {pname} | {} | {} | {} | {} | {} | {} | {} | {:.1} % | {} | {} | {} | {} |",
                                us(net_hot),
                                us(quantile(&hot, 0.5)),
                                us(quantile(f, 0.5)),
                                us(quantile(f, 0.99)),
                                us(f.last().copied().unwrap_or(0)),
                                us(quantile(s, 0.5)),
                                us(quantile(s, 0.99)),
                                us(quantile(s, 0.999)),
                                us(s.last().copied().unwrap_or(0)),
                                100.0 * f.len() as f64 / s.len().max(1) as f64,
                                r.host_stolen,
                                r.late,
                                r.stolen,
                                steal_ms() - steal0,
                            );
                        }
                    }
                }
            }
        }
    }
    println!("\n(bench ran {:.0} s)", (monotonic_ns() - t0) as f64 / 1e9);
}

//! Training-throughput bench of the hand-written trainer (plain timed main, `harness = false`):
//! 200k × 40 synthetic friction samples, hidden 268/215, batch 4096, dropout 0.1, λ 0.1, Adam lr 1e-3,
//! 2 threads, no validation set — the workload of `benches/train_vs_pytorch.py`.
//!
//! `FRICTL_BENCH_EPOCHS` (default 5) sets the number of timed epochs; the first epoch is a warm-up and
//! not counted when more than one runs. Prints each epoch (wall time, and CPU time of all threads,
//! which a loaded machine inflates far less), then `FRICTL_EPOCH_S=<median wall seconds>` and
//! `FRICTL_EPOCH_CPU_S=<median CPU seconds>` (parsed by `benches/train_compare.sh`) and the
//! projection for a paper-size run.
//!
//! `FRICTL_BENCH_GEMM=1` instead times the eight GEMM shapes of one training step on their own
//! (`gemm` crate, single thread, thread CPU time — robust to a loaded machine) and prints GFMA/s per
//! shape: where an epoch's arithmetic goes.

use std::ops::ControlFlow;
use std::time::Instant;

use frictionless_train::{TrainConfig, Trainer, synthetic};

/// CPU time of `clock` in seconds: `CLOCK_PROCESS_CPUTIME_ID` (all threads of the process) or
/// `CLOCK_THREAD_CPUTIME_ID` (this thread; unaffected by time spent descheduled on a loaded machine).
fn cpu_s(clock: libc::clockid_t) -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, exclusively borrowed timespec.
    unsafe { libc::clock_gettime(clock, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// CPU time of the whole process (all threads) in seconds.
fn process_cpu_s() -> f64 {
    cpu_s(libc::CLOCK_PROCESS_CPUTIME_ID)
}

/// Thread CPU time in seconds.
fn thread_cpu_s() -> f64 {
    cpu_s(libc::CLOCK_THREAD_CPUTIME_ID)
}

/// `dst[m×n] row-major = lhs[m×k] · rhs[k×n]`, operands given as (data, row stride, column stride);
/// the same `gemm` call convention as the trainer (`gemm` takes column stride before row stride).
#[allow(clippy::too_many_arguments)]
fn gemm_rm(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    lhs: (&[f32], usize, usize),
    rhs: (&[f32], usize, usize),
    par: gemm::Parallelism,
) {
    assert!(dst.len() >= m * n);
    assert!((m - 1) * lhs.1 + (k - 1) * lhs.2 < lhs.0.len());
    assert!((k - 1) * rhs.1 + (n - 1) * rhs.2 < rhs.0.len());
    // SAFETY: extents checked above; dst does not alias the operands.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            n as isize,
            false,
            lhs.0.as_ptr(),
            lhs.2 as isize,
            lhs.1 as isize,
            rhs.0.as_ptr(),
            rhs.2 as isize,
            rhs.1 as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            par,
        )
    }
}

/// Times the GEMM shapes of one step of the bench network (batch 4096, 40 → 268 → 215 → 1).
fn gemm_shapes() {
    let (b, n0, n1, n2) = (4096usize, 40usize, 268usize, 215usize);
    let fill = |len: usize| -> Vec<f32> {
        (0..len)
            .map(|i| ((i * 7919) % 1000) as f32 * 1e-3 - 0.5)
            .collect()
    };
    let (x, a1, a2) = (fill(b * n0), fill(b * n1), fill(b * n2));
    let (w1, w2, w3) = (fill(n1 * n0), fill(n2 * n1), fill(n2));
    let (dz1, dz2, dz3) = (fill(b * n1), fill(b * n2), fill(b));
    let mut dst = vec![0f32; b * n1];
    // (name, m, n, k, lhs (data, rs, cs), rhs (data, rs, cs)) — forward, then backward.
    type Op<'a> = (
        &'static str,
        usize,
        usize,
        usize,
        (&'a [f32], usize, usize),
        (&'a [f32], usize, usize),
    );
    let ops: Vec<Op<'_>> = vec![
        ("fwd1 X·W1ᵀ", b, n1, n0, (&x, n0, 1), (&w1, 1, n0)),
        ("fwd2 A1·W2ᵀ", b, n2, n1, (&a1, n1, 1), (&w2, 1, n1)),
        ("fwd3 A2·W3ᵀ", b, 1, n2, (&a2, n2, 1), (&w3, 1, n2)),
        ("dW3 dZ3ᵀ·A2", 1, n2, b, (&dz3, 1, 1), (&a2, n2, 1)),
        ("dA2 dZ3·W3", b, n2, 1, (&dz3, 1, 1), (&w3, n2, 1)),
        ("dW2 dZ2ᵀ·A1", n2, n1, b, (&dz2, 1, n2), (&a1, n1, 1)),
        ("dA1 dZ2·W2", b, n1, n2, (&dz2, n2, 1), (&w2, n1, 1)),
        ("dW1 dZ1ᵀ·X", n1, n0, b, (&dz1, 1, n1), (&x, n0, 1)),
    ];
    let reps = 20;
    let (mut total_fma, mut total_s) = (0f64, 0f64);
    for (name, m, n, k, lhs, rhs) in ops {
        gemm_rm(m, n, k, &mut dst, lhs, rhs, gemm::Parallelism::None);
        let t0 = thread_cpu_s();
        for _ in 0..reps {
            gemm_rm(m, n, k, &mut dst, lhs, rhs, gemm::Parallelism::None);
        }
        let s = (thread_cpu_s() - t0) / reps as f64;
        let fma = (m * n * k) as f64;
        total_fma += fma;
        total_s += s;
        println!(
            "{name:14} m {m:5} n {n:4} k {k:5}: {:8.3} ms  {:6.1} GFMA/s (1 thread, CPU time)",
            s * 1e3,
            fma / s * 1e-9
        );
    }
    println!(
        "one step: {:.1} MFMA in {:.2} ms CPU = {:.1} GFMA/s; × 49 steps = {:.3} s CPU per 200k epoch",
        total_fma * 1e-6,
        total_s * 1e3,
        total_fma / total_s * 1e-9,
        total_s * 49.0
    );
}

fn main() {
    if std::env::var_os("FRICTL_BENCH_GEMM").is_some() {
        gemm_shapes();
        return;
    }
    let epochs: usize = std::env::var("FRICTL_BENCH_EPOCHS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5)
        .max(1);
    let threads: usize = std::env::var("FRICTL_BENCH_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2)
        .max(1);
    let t0 = Instant::now();
    let data = synthetic::friction_task(200_000, 20, 1);
    eprintln!(
        "data: {} × {} in {:.2} s",
        data.y_label_nm.len(),
        data.n_inputs,
        t0.elapsed().as_secs_f64()
    );
    let cfg = TrainConfig {
        hidden: vec![268, 215],
        dropout: 0.1,
        lambda: 0.1,
        lr: 1e-3,
        batch_size: 4096,
        epochs,
        seed: 0,
        threads,
        patience: None,
        abort_loss: None,
    };
    let t0 = Instant::now();
    let mut t = Trainer::new(cfg, &data.dataset(), None).expect("valid bench configuration");
    eprintln!(
        "setup (normalisation, init, buffers): {:.2} s",
        t0.elapsed().as_secs_f64()
    );
    let (mut secs, mut cpu_secs) = (Vec::new(), Vec::new());
    let mut cpu0 = process_cpu_s();
    t.train(|r| {
        let cpu = process_cpu_s();
        println!(
            "epoch {:3}: {:.3} s  (CPU {:.3} s, all threads)  train loss {:.5}",
            r.epoch,
            r.seconds,
            cpu - cpu0,
            r.train_loss
        );
        secs.push(r.seconds);
        cpu_secs.push(cpu - cpu0);
        cpu0 = cpu;
        ControlFlow::Continue(())
    })
    .expect("training runs");
    let median = |v: &mut Vec<f64>| {
        if v.len() > 1 {
            v.remove(0);
        }
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (median, cpu_median) = (median(&mut secs), median(&mut cpu_secs));
    println!("FRICTL_EPOCH_S={median:.4}");
    println!("FRICTL_EPOCH_CPU_S={cpu_median:.4}");
    println!(
        "threads {threads}: {:.0} samples/s; projected 350 epochs: {:.1} min at 200k samples, {:.1} min at 300k",
        200_000.0 / median,
        350.0 * median / 60.0,
        350.0 * median * 1.5 / 60.0
    );
}

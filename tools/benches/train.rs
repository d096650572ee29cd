//! Training-throughput bench of the hand-written trainer (plain timed main, `harness = false`):
//! 200k × 40 synthetic friction samples, hidden 268/215, batch 4096, dropout 0.1, λ 0.1, Adam lr 1e-3,
//! 2 threads, no validation set — the workload of `benches/train_vs_pytorch.py`.
//!
//! `FRICTL_BENCH_EPOCHS` (default 5) sets the number of timed epochs; the first epoch is a warm-up and
//! not counted when more than one runs. Prints each epoch, then `FRICTL_EPOCH_S=<median seconds>`
//! (parsed by `benches/train_compare.sh`) and the projection for a paper-size run.

use std::ops::ControlFlow;
use std::time::Instant;

use frictl::train::{TrainConfig, Trainer, synthetic};

fn main() {
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
    let mut secs = Vec::new();
    t.train(|r| {
        println!(
            "epoch {:3}: {:.3} s  train loss {:.5}",
            r.epoch, r.seconds, r.train_loss
        );
        secs.push(r.seconds);
        ControlFlow::Continue(())
    })
    .expect("training runs");
    if secs.len() > 1 {
        secs.remove(0);
    }
    secs.sort_by(f64::total_cmp);
    let median = secs[secs.len() / 2];
    println!("FRICTL_EPOCH_S={median:.4}");
    println!(
        "threads {threads}: {:.0} samples/s; projected 350 epochs: {:.1} min at 200k samples, {:.1} min at 300k",
        200_000.0 / median,
        350.0 * median / 60.0,
        350.0 * median * 1.5 / 60.0
    );
}

//! Reproducibility of the trainer: the same seed gives bit-identical weights on 2 rayon threads, a
//! different seed does not, and stopping, checkpointing and resuming gives exactly the uninterrupted run.

use frictionless_train::{TrainConfig, TrainError, Trainer, synthetic};
use std::ops::ControlFlow;

fn cfg(seed: u64, threads: usize) -> TrainConfig {
    TrainConfig {
        hidden: vec![32, 24],
        dropout: 0.1,
        lambda: 0.2,
        lr: 1e-3,
        batch_size: 128, // 3000 rows: 23 full batches and a partial one
        epochs: 6,
        seed,
        threads,
        patience: None,
        abort_loss: Some(1000.0),
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn data() -> (synthetic::SyntheticData, synthetic::SyntheticData) {
    (
        synthetic::friction_task(3000, 4, 5),
        synthetic::friction_task(600, 4, 6),
    )
}

fn full_run(seed: u64, threads: usize) -> (Vec<u32>, Vec<u32>, Vec<f64>) {
    let (tr, va) = data();
    let mut t = Trainer::new(cfg(seed, threads), &tr.dataset(), Some(&va.dataset())).unwrap();
    let out = t.train(|_| ControlFlow::Continue(())).unwrap();
    let best: Vec<f32> = out
        .weights
        .layers
        .iter()
        .flat_map(|l| l.weight.iter().chain(&l.bias).copied())
        .collect();
    (
        bits(t.params()),
        bits(&best),
        out.history.iter().map(|h| h.train_loss).collect(),
    )
}

#[test]
fn same_seed_gives_bit_identical_weights() {
    let a = full_run(42, 2);
    let b = full_run(42, 2);
    assert_eq!(
        a.0, b.0,
        "final parameters differ between two runs with the same seed"
    );
    assert_eq!(a.1, b.1, "best weights differ");
    assert_eq!(a.2, b.2, "loss histories differ");
    let c = full_run(43, 2);
    assert_ne!(a.0, c.0, "a different seed gave the same weights");
}

#[test]
fn checkpoint_resume_equals_uninterrupted_run() {
    let (tr, va) = data();
    let uninterrupted = full_run(7, 2);

    let dir = std::env::temp_dir().join(format!("frictl_train_ckpt_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.ckpt");
    {
        let mut t = Trainer::new(cfg(7, 2), &tr.dataset(), Some(&va.dataset())).unwrap();
        let out = t
            .train(|r| {
                if r.epoch == 3 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            })
            .unwrap();
        assert!(out.interrupted);
        assert_eq!(t.epochs_done(), 3);
        t.save_checkpoint(&path).unwrap();
    } // the first trainer is gone: everything must come from the file
    let mut r = Trainer::resume(&path, &tr.dataset(), Some(&va.dataset())).unwrap();
    assert_eq!(r.epochs_done(), 3);
    let out = r.train(|_| ControlFlow::Continue(())).unwrap();
    assert!(!out.interrupted);
    let best: Vec<f32> = out
        .weights
        .layers
        .iter()
        .flat_map(|l| l.weight.iter().chain(&l.bias).copied())
        .collect();
    assert_eq!(
        bits(r.params()),
        uninterrupted.0,
        "resumed final parameters differ from the uninterrupted run"
    );
    assert_eq!(bits(&best), uninterrupted.1, "resumed best weights differ");
    assert_eq!(
        out.history.iter().map(|h| h.train_loss).collect::<Vec<_>>(),
        uninterrupted.2
    );

    // Resuming with other data is refused, naming the file.
    let other = synthetic::friction_task(3000, 4, 99);
    let e = Trainer::resume(&path, &other.dataset(), Some(&va.dataset()))
        .err()
        .unwrap();
    assert!(matches!(e, TrainError::Checkpoint { .. }), "{e}");
    assert!(e.to_string().contains("run.ckpt"), "{e}");
    // A file that is not a checkpoint is refused too.
    std::fs::write(&path, b"not a checkpoint").unwrap();
    assert!(matches!(
        Trainer::resume(&path, &tr.dataset(), Some(&va.dataset())),
        Err(TrainError::Checkpoint { .. })
    ));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cosine_decay_runs_from_lr_to_the_final_rate_and_changes_the_weights() {
    let (tr, va) = data();
    let mut t = Trainer::new(cfg(9, 2), &tr.dataset(), Some(&va.dataset())).unwrap();
    assert!(
        t.set_cosine_decay(2e-3).is_err(),
        "a final rate above lr is refused"
    );
    assert!(t.set_cosine_decay(f32::NAN).is_err());
    t.set_cosine_decay(1e-5).unwrap();
    let lrs: Vec<f32> = (1..=6).map(|e| t.lr_of_epoch(e)).collect();
    assert!(
        (lrs[0] - 1e-3).abs() < 1e-9 && (lrs[5] - 1e-5).abs() < 1e-9,
        "{lrs:?}"
    );
    assert!(lrs.windows(2).all(|w| w[1] < w[0]), "{lrs:?}");
    t.train(|_| ControlFlow::Continue(())).unwrap();
    let decayed = bits(t.params());
    let mut c = Trainer::new(cfg(9, 2), &tr.dataset(), Some(&va.dataset())).unwrap();
    assert!(
        (c.lr_of_epoch(6) - 1e-3).abs() < 1e-12,
        "constant without decay"
    );
    c.train(|_| ControlFlow::Continue(())).unwrap();
    assert_ne!(
        decayed,
        bits(c.params()),
        "the decay is applied to the steps"
    );
}

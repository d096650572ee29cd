//! The trainer learns a synthetic friction-like task: the loss falls, the result beats a constant
//! predictor by a wide margin, and the exported `MlpWeights` (normalisation included) reproduce the
//! trainer's own batched predictions through the independent reference forward pass.

use frictionless_train::{Dataset, Predictor, TrainConfig, TrainError, Trainer, rmse, synthetic};
use std::ops::ControlFlow;

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-5 * b.abs().max(1.0)
}

#[test]
fn training_learns_and_export_matches_reference_forward() {
    let train = synthetic::friction_task(20_000, 5, 11);
    let val = synthetic::friction_task(4_000, 5, 12);
    let cfg = TrainConfig {
        hidden: vec![64, 64],
        dropout: 0.05,
        lambda: 0.1,
        lr: 2e-3,
        batch_size: 256,
        epochs: 15,
        seed: 3,
        threads: 2,
        ..TrainConfig::default()
    };
    let mut t = Trainer::new(cfg, &train.dataset(), Some(&val.dataset())).unwrap();
    let mut seen = 0;
    let out = t
        .train(|r| {
            seen += 1;
            assert_eq!(r.epoch, seen);
            ControlFlow::Continue(())
        })
        .unwrap();
    assert_eq!(seen, 15);
    let h = &out.history;
    assert!(
        h[h.len() - 1].train_loss < h[0].train_loss / 3.0,
        "loss did not fall enough: {:?}",
        h.iter().map(|r| r.train_loss).collect::<Vec<_>>()
    );

    // A constant predictor (the training-label mean) against the best network on validation data.
    let mean =
        train.y_label_nm.iter().map(|&v| v as f64).sum::<f64>() / train.y_label_nm.len() as f64;
    let constant = rmse(&vec![mean as f32; val.y_label_nm.len()], &val.y_label_nm);
    let best = out.best_val_rmse_nm.unwrap();
    assert!(
        best < 0.25 * constant,
        "validation RMSE {best} vs constant predictor {constant}"
    );
    eprintln!(
        "validation RMSE {best:.4} Nm, constant predictor {constant:.4} Nm, best epoch {}",
        out.best_epoch
    );

    // Exported best weights through the batched evaluator and through the reference forward pass.
    let mut p = Predictor::new(&out.weights, 2).unwrap();
    let pred = p.predict(&val.x).unwrap();
    assert!((rmse(&pred, &val.y_label_nm) - best).abs() <= 1e-6 * best);
    for (row, &y) in val.x.chunks_exact(val.n_inputs).zip(&pred).take(500) {
        let r = out.weights.forward_reference(row)[0];
        assert!(close(y, r), "evaluator {y} vs reference {r}");
    }
    // The trainer's own batched predictions for its current weights.
    let own = t.predict(&val.x[..200 * val.n_inputs]).unwrap();
    let current = t.weights();
    current.validate().unwrap();
    for (row, &y) in val.x.chunks_exact(val.n_inputs).zip(&own) {
        let r = current.forward_reference(row)[0];
        assert!(close(y, r), "trainer {y} vs reference {r}");
    }
}

#[test]
fn normalisation_is_fitted_on_training_data_only() {
    let train = synthetic::friction_task(2_000, 3, 21);
    let mut val = synthetic::friction_task(500, 3, 22);
    for v in &mut val.x {
        *v = *v * 10.0 + 5.0; // a validation set with very different statistics
    }
    let cfg = TrainConfig {
        hidden: vec![8],
        epochs: 1,
        batch_size: 512,
        ..TrainConfig::default()
    };
    let a = Trainer::new(cfg.clone(), &train.dataset(), Some(&val.dataset())).unwrap();
    let b = Trainer::new(cfg, &train.dataset(), None).unwrap();
    assert_eq!(a.normalisation(), b.normalisation());
    assert_eq!(
        a.normalisation(),
        &frictionless_train::fit_normalisation(&train.x, train.n_inputs)
    );
}

#[test]
fn bad_inputs_are_typed_errors() {
    let mut d = synthetic::friction_task(100, 2, 1);
    d.x[17] = f32::NAN;
    let e = Trainer::new(TrainConfig::default(), &d.dataset(), None)
        .err()
        .unwrap();
    assert!(
        matches!(&e, TrainError::Data { what, .. } if what == "x"),
        "{e}"
    );
    assert!(e.to_string().contains("index 17"), "{e}");

    let d = synthetic::friction_task(100, 2, 1);
    let short = Dataset {
        y_scv_nm: &d.y_scv_nm[..99],
        ..d.dataset()
    };
    assert!(matches!(
        Trainer::new(TrainConfig::default(), &short, None),
        Err(TrainError::Data { .. })
    ));
    for cfg in [
        TrainConfig {
            hidden: vec![],
            ..TrainConfig::default()
        },
        TrainConfig {
            hidden: vec![8; 5],
            ..TrainConfig::default()
        },
        TrainConfig {
            dropout: 1.0,
            ..TrainConfig::default()
        },
        TrainConfig {
            lambda: 1.5,
            ..TrainConfig::default()
        },
        TrainConfig {
            lr: f32::NAN,
            ..TrainConfig::default()
        },
        TrainConfig {
            batch_size: 0,
            ..TrainConfig::default()
        },
    ] {
        assert!(matches!(
            Trainer::new(cfg, &d.dataset(), None),
            Err(TrainError::Config(_))
        ));
    }
}

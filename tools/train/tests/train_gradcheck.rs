//! Gradient check of the hand-written backward pass: central finite differences (ε = 1e-3) of the
//! eval-mode loss on a batch of 64 rows against the analytic gradient, for parameters drawn from every
//! tensor of networks with two and three hidden layers.

use frictionless_train::{TrainConfig, Trainer, synthetic};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn check(hidden: Vec<usize>, seed: u64) {
    let data = synthetic::friction_task(512, 5, seed);
    let cfg = TrainConfig {
        hidden,
        dropout: 0.1,
        lambda: 0.3,
        batch_size: 256,
        epochs: 1,
        seed,
        threads: 2,
        ..TrainConfig::default()
    };
    let mut t = Trainer::new(cfg, &data.dataset(), None).unwrap();
    let rows: Vec<usize> = (0..64).map(|i| i * 7).collect();
    let (_, grad) = t.loss_and_gradient(&rows).unwrap();
    let tensors = t.param_tensors();
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xABCD);
    let eps = 1e-3f32;
    let (mut worst, mut checked, mut largest_grad) = (0f64, 0, 0f64);
    // Round-robin over every tensor until 56 parameters are checked (as in the reference check).
    for (name, range) in tensors.iter().cycle().take(56) {
        let i = rng.random_range(range.clone());
        let p0 = t.params()[i];
        t.params_mut()[i] = p0 + eps;
        let (lp, _) = t.loss_and_gradient(&rows).unwrap();
        t.params_mut()[i] = p0 - eps;
        let (lm, _) = t.loss_and_gradient(&rows).unwrap();
        t.params_mut()[i] = p0;
        // The perturbation actually applied (p0 ± eps is rounded to f32).
        let h = ((p0 + eps) as f64 - (p0 - eps) as f64) / 2.0;
        let fd = (lp - lm) / (2.0 * h);
        let an = grad[i] as f64;
        let rel = (fd - an).abs() / (fd.abs() + an.abs()).max(1e-2);
        assert!(
            rel < 5e-2,
            "{name}[{}]: finite difference {fd:.6e}, analytic {an:.6e}, rel {rel:.3e}",
            i - range.start
        );
        worst = worst.max(rel);
        largest_grad = largest_grad.max(an.abs());
        checked += 1;
    }
    assert!(checked >= 50, "only {checked} parameters checked");
    assert!(
        largest_grad > 1e-2,
        "gradients all tiny ({largest_grad}): the check would be vacuous"
    );
    eprintln!(
        "hidden layers {}: {checked} parameters, worst relative error {worst:.3e}",
        tensors.len() / 2 - 1
    );
}

#[test]
fn gradient_matches_finite_differences_two_hidden_layers() {
    check(vec![24, 16], 1);
}

#[test]
fn gradient_matches_finite_differences_three_hidden_layers() {
    check(vec![20, 12, 8], 2);
}

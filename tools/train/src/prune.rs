//! Structured pruning of a ReLU MLP into a narrower network of the same depth: the starting point of
//! `frictl distill --init prune`.
//!
//! What it **is**: [`prune`] keeps, in every hidden layer, the units that carry the most of what the
//! teacher passes on (spread of the unit's activation on the given inputs times the norm of its outgoing
//! weights), and refits each following layer by least squares so that it reproduces the **teacher's**
//! pre-activations of that layer from the kept units alone (ridge-regularised normal equations; a
//! dropped unit's mean contribution lands in the bias). Errors do not pile up layer after layer: every
//! refit aims at the teacher's own values, from the pruned network's actual activations. The result
//! already computes close to what the teacher computes on inputs like the given ones, so fine-tuning
//! ([`crate::Trainer::from_init`]) starts from the teacher's function instead of from noise.
//!
//! What it is **not**: a trainer, and not a storage change (`frictl convert` rounds weights; this
//! removes units). The first layer's kept rows are the teacher's own; the input normalisation is the
//! teacher's.

use frictionless::mlp::{Activation, DenseLayer, MlpWeights};
use nalgebra::DMatrix;
use thiserror::Error;

/// Why a network cannot be pruned to the asked widths.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PruneError {
    /// The student's hidden layers do not match the teacher's in number, or one is wider.
    #[error(
        "pruning keeps the teacher's depth and narrows each hidden layer: teacher hidden {teacher:?}, \
         asked {asked:?} (as many layers, each 1 ..= the teacher's width)"
    )]
    Widths {
        /// The teacher's hidden widths.
        teacher: Vec<usize>,
        /// The asked widths.
        asked: Vec<usize>,
    },
    /// The teacher is not ReLU hidden layers with one linear output.
    #[error("only ReLU hidden layers with one linear output can be pruned")]
    Architecture,
    /// No inputs, or a length that is not a whole number of rows.
    #[error("pruning needs whole input rows of {n_in} values, got {len} values")]
    Inputs {
        /// Inputs per row.
        n_in: usize,
        /// Values given.
        len: usize,
    },
}

/// The pruned network: `hidden[l]` units of the teacher's hidden layer `l`, the following layers refitted
/// on `x` (raw inputs, row-major, `teacher`'s input count per row; normalised here with the teacher's
/// normalisation, which the result keeps).
pub fn prune(teacher: &MlpWeights, hidden: &[usize], x: &[f32]) -> Result<MlpWeights, PruneError> {
    let layers = &teacher.layers;
    let teacher_hidden: Vec<usize> = layers[..layers.len().saturating_sub(1)]
        .iter()
        .map(|l| l.n_out)
        .collect();
    let shaped = !layers.is_empty()
        && layers.last().is_some_and(|l| l.n_out == 1)
        && layers.iter().enumerate().all(|(k, l)| {
            l.activation
                == if k + 1 == layers.len() {
                    Activation::Identity
                } else {
                    Activation::Relu
                }
        });
    if !shaped {
        return Err(PruneError::Architecture);
    }
    if hidden.len() != teacher_hidden.len()
        || hidden
            .iter()
            .zip(&teacher_hidden)
            .any(|(&h, &t)| h == 0 || h > t)
    {
        return Err(PruneError::Widths {
            teacher: teacher_hidden,
            asked: hidden.to_vec(),
        });
    }
    let n_in = layers[0].n_in;
    if x.is_empty() || !x.len().is_multiple_of(n_in) {
        return Err(PruneError::Inputs { n_in, len: x.len() });
    }
    let n = x.len() / n_in;
    let input = DMatrix::from_fn(n, n_in, |r, c| {
        (f64::from(x[r * n_in + c]) - f64::from(teacher.norm.mean[c]))
            / f64::from(teacher.norm.scale[c])
    });

    // The teacher's pre-activations of every layer: what each refit aims at.
    let mut targets = Vec::with_capacity(layers.len());
    let mut a = input.clone();
    for (k, l) in layers.iter().enumerate() {
        let z = affine(&a, l);
        if k + 1 < layers.len() {
            a = z.map(|v| v.max(0.0));
        }
        targets.push(z);
    }

    let mut out = Vec::with_capacity(layers.len());
    // The layer being built (all of the teacher's units for now): weights [n_out][n_in] and biases.
    let mut w = DMatrix::from_fn(layers[0].n_out, n_in, |r, c| {
        f64::from(layers[0].weight[r * n_in + c])
    });
    let mut b: Vec<f64> = layers[0].bias.iter().map(|&v| f64::from(v)).collect();
    let mut z = targets[0].clone();
    for (l, &keep_n) in hidden.iter().enumerate() {
        let act = z.map(|v| v.max(0.0));
        let next = &layers[l + 1];
        let keep = strongest_units(&act, next, keep_n);
        out.push(DenseLayer {
            n_in: w.ncols(),
            n_out: keep.len(),
            weight: keep
                .iter()
                .flat_map(|&r| {
                    let w = &w;
                    (0..w.ncols()).map(move |c| w[(r, c)] as f32)
                })
                .collect(),
            bias: keep.iter().map(|&r| b[r] as f32).collect(),
            activation: Activation::Relu,
        });
        // The kept activations and a column of ones (the bias).
        let p = DMatrix::from_fn(n, keep.len() + 1, |r, c| {
            keep.get(c).map_or(1.0, |&u| act[(r, u)])
        });
        let theta = ridge_solve(&p, &targets[l + 1]);
        z = &p * &theta;
        let k = keep.len();
        w = theta.rows(0, k).transpose();
        b = theta.row(k).iter().copied().collect();
    }
    out.push(DenseLayer {
        n_in: w.ncols(),
        n_out: 1,
        weight: w.iter().map(|&v| v as f32).collect(),
        bias: b.iter().map(|&v| v as f32).collect(),
        activation: Activation::Identity,
    });
    Ok(MlpWeights {
        norm: teacher.norm.clone(),
        layers: out,
    })
}

/// `a · Wᵀ + b` for a layer of the teacher.
fn affine(a: &DMatrix<f64>, l: &DenseLayer) -> DMatrix<f64> {
    let w = DMatrix::from_fn(l.n_in, l.n_out, |r, c| f64::from(l.weight[c * l.n_in + r]));
    let mut z = a * w;
    for (c, &bias) in l.bias.iter().enumerate() {
        z.column_mut(c).add_scalar_mut(f64::from(bias));
    }
    z
}

/// The `keep` units of `act` (rows: inputs, columns: units) that pass the most on to `next`: standard
/// deviation of the activation times the norm of the unit's outgoing weights. In the units' order.
fn strongest_units(act: &DMatrix<f64>, next: &DenseLayer, keep: usize) -> Vec<usize> {
    let n = act.nrows() as f64;
    let mut score: Vec<(f64, usize)> = (0..act.ncols())
        .map(|u| {
            let col = act.column(u);
            let mean = col.sum() / n;
            let var = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
            let out_norm = (0..next.n_out)
                .map(|o| f64::from(next.weight[o * next.n_in + u]).powi(2))
                .sum::<f64>()
                .sqrt();
            (var.sqrt() * out_norm, u)
        })
        .collect();
    // Strongest first; ties by unit index, for a deterministic choice.
    score.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut kept: Vec<usize> = score[..keep].iter().map(|&(_, u)| u).collect();
    kept.sort_unstable();
    kept
}

/// Least squares `p · θ ≈ t` through the normal equations with a small ridge (units dead on every
/// input give zero columns). Cholesky of `pᵀp + εI`; ε grows until it factors.
fn ridge_solve(p: &DMatrix<f64>, t: &DMatrix<f64>) -> DMatrix<f64> {
    let gram = p.transpose() * p;
    let rhs = p.transpose() * t;
    let scale = (gram.trace() / gram.nrows() as f64).max(1e-12);
    let mut eps = 1e-9 * scale;
    loop {
        let mut g = gram.clone();
        for i in 0..g.nrows() {
            g[(i, i)] += eps;
        }
        if let Some(ch) = g.cholesky() {
            return ch.solve(&rhs);
        }
        eps *= 100.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rmse;
    use frictionless::kernel::Mlp;
    use frictionless::mlp::StorageDtype;
    use frictionless::random::{NormInit, RandomMlpSpec, WeightInit, seeded_mlp};
    use rand::{Rng, SeedableRng};

    /// Outputs of `m` on the rows of `x`, on the kernel frictiond runs (f32).
    fn forward(m: &MlpWeights, x: &[f32]) -> Vec<f32> {
        let mut k = Mlp::new(m, StorageDtype::F32).unwrap();
        x.chunks(m.layers[0].n_in)
            .map(|row| k.forward(row))
            .collect()
    }

    fn teacher(sizes: &[usize]) -> MlpWeights {
        seeded_mlp(
            &RandomMlpSpec {
                sizes: sizes.to_vec(),
                weights: WeightInit::Uniform { amp: 0.4 },
                bias: -0.1..0.1,
                norm: NormInit::Identity,
            },
            3,
        )
        .unwrap()
    }

    /// `n` rows of `n_in` inputs, uniform in [−1, 1).
    fn inputs(n: usize, n_in: usize, seed: u64) -> Vec<f32> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n * n_in).map(|_| rng.random_range(-1.0..1.0)).collect()
    }

    #[test]
    fn keeping_every_unit_reproduces_the_teacher() {
        let t = teacher(&[6, 12, 9, 1]);
        let x = inputs(2000, 6, 1);
        let p = prune(&t, &[12, 9], &x).unwrap();
        let probe = inputs(500, 6, 2);
        let err = rmse(&forward(&p, &probe), &forward(&t, &probe));
        assert!(err < 1e-4, "full-width refit is off by {err}");
    }

    #[test]
    fn a_unit_that_never_fires_is_dropped_without_loss() {
        let mut t = teacher(&[4, 8, 1]);
        // Unit 3 never fires: zero weights, negative bias.
        for i in 0..4 {
            t.layers[0].weight[3 * 4 + i] = 0.0;
        }
        t.layers[0].bias[3] = -1.0;
        // Unit 5 is constant (fires with the same value on every input): its mean goes to the bias.
        for i in 0..4 {
            t.layers[0].weight[5 * 4 + i] = 0.0;
        }
        t.layers[0].bias[5] = 0.7;
        let x = inputs(3000, 4, 5);
        let p = prune(&t, &[6], &x).unwrap();
        assert_eq!(p.layers[0].n_out, 6);
        let probe = inputs(800, 4, 6);
        let err = rmse(&forward(&p, &probe), &forward(&t, &probe));
        assert!(
            err < 1e-4,
            "dropping a dead and a constant unit costs {err}"
        );
    }

    /// A random teacher has no spare units (a trained one does), so the bound is loose: cutting 64 → 24
    /// and 32 → 12 units and keeping the other weights as they were leaves about the teacher's spread.
    #[test]
    fn narrower_refits_beat_plain_truncation() {
        let t = teacher(&[8, 64, 32, 1]);
        let x = inputs(8000, 8, 9);
        let probe = inputs(2000, 8, 10);
        let y = forward(&t, &probe);
        let p = prune(&t, &[24, 12], &x).unwrap();
        let pruned = rmse(&forward(&p, &probe), &y);
        // Plain truncation: the first 24 and 12 units, the other weights as they were.
        let mut cut = t.clone();
        cut.layers[0].weight.truncate(24 * 8);
        cut.layers[0].bias.truncate(24);
        cut.layers[0].n_out = 24;
        cut.layers[1].weight = (0..12)
            .flat_map(|o| t.layers[1].weight[o * 64..o * 64 + 24].to_vec())
            .collect();
        cut.layers[1].bias.truncate(12);
        cut.layers[1].n_in = 24;
        cut.layers[1].n_out = 12;
        cut.layers[2].weight.truncate(12);
        cut.layers[2].n_in = 12;
        let truncated = rmse(&forward(&cut, &probe), &y);
        let spread = rmse(&y, &vec![y.iter().sum::<f32>() / y.len() as f32; y.len()]);
        assert!(
            pruned < 0.75 * truncated && pruned < 0.75 * spread,
            "pruned {pruned}, truncated {truncated}, teacher spread {spread}"
        );
    }

    #[test]
    fn wrong_widths_and_inputs_are_refused() {
        let t = teacher(&[4, 8, 6, 1]);
        let x = inputs(10, 4, 1);
        assert!(matches!(
            prune(&t, &[4], &x),
            Err(PruneError::Widths { .. })
        ));
        assert!(matches!(
            prune(&t, &[9, 6], &x),
            Err(PruneError::Widths { .. })
        ));
        assert!(matches!(
            prune(&t, &[0, 6], &x),
            Err(PruneError::Widths { .. })
        ));
        assert!(matches!(
            prune(&t, &[4, 3], &x[..7]),
            Err(PruneError::Inputs { n_in: 4, len: 7 })
        ));
        assert!(matches!(
            prune(&t, &[4, 3], &[]),
            Err(PruneError::Inputs { .. })
        ));
    }
}

//! Seeded random ReLU networks (cargo feature `random`).
//!
//! What it is: [`seeded_mlp`], the one builder of reproducible random [`MlpWeights`] that tests,
//! benches and tools use when they need "some valid friction network" of a given shape (kernel parity,
//! weight-file round trips, daemon and ONNX tests). The same [`RandomMlpSpec`] and seed always give the
//! same weights (ChaCha8 stream, independent of platform).
//!
//! What it is not: a training initialiser (the trainer in `frictl` owns its own), nor part of the
//! real-time core — it is compiled only with the `random` feature, so `frictiond` does not carry `rand`
//! unless a build asks for it.

use std::ops::Range;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use thiserror::Error;

use crate::mlp::{Activation, DenseLayer, MlpShapeError, MlpWeights, Normalisation, limits};

/// How the dense weights are drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WeightInit {
    /// Every weight uniform in `[−amp, amp)`.
    Uniform {
        /// Half-width of the interval (> 0).
        amp: f32,
    },
    /// He-uniform: weights of a layer with `n_in` inputs uniform in `±√(6/n_in)`, so activations
    /// neither die nor explode with depth.
    HeUniform,
}

/// How the input normalisation is chosen.
#[derive(Clone, Debug, PartialEq)]
pub enum NormInit {
    /// mean 0, scale 1 (no random draws).
    Identity,
    /// Every mean uniform in `mean`, every scale uniform in `scale` (both half-open ranges).
    Uniform {
        /// Range of the per-input means.
        mean: Range<f32>,
        /// Range of the per-input scales (must not produce 0: keep it on one side of zero).
        scale: Range<f32>,
    },
}

/// The shape and distributions of a random network: hidden layers ReLU, output layer linear (the
/// only activations [`MlpWeights::validate`] accepts).
#[derive(Clone, Debug, PartialEq)]
pub struct RandomMlpSpec {
    /// Layer sizes including input and output, e.g. `[40, 268, 215, 1]`.
    pub sizes: Vec<usize>,
    /// Distribution of the weights.
    pub weights: WeightInit,
    /// Every bias uniform in this half-open range.
    pub bias: Range<f32>,
    /// Input normalisation.
    pub norm: NormInit,
}

impl RandomMlpSpec {
    /// A generic test network of `sizes`: weights uniform in ±0.5, biases in ±0.1, normalisation means
    /// in ±2 and scales in [0.1, 3). Change single fields with struct-update syntax.
    pub fn new(sizes: &[usize]) -> Self {
        Self {
            sizes: sizes.to_vec(),
            weights: WeightInit::Uniform { amp: 0.5 },
            bias: -0.1..0.1,
            norm: NormInit::Uniform {
                mean: -2.0..2.0,
                scale: 0.1..3.0,
            },
        }
    }
}

/// Why [`seeded_mlp`] could not build a network.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RandomMlpError {
    /// The sizes do not describe an acceptable network (checked before any allocation).
    #[error("random MLP sizes: {0}")]
    Shape(#[from] MlpShapeError),
    /// A range is empty, reversed or not finite.
    #[error("random MLP {what}: range {lo}..{hi} is empty or not finite")]
    Range {
        /// Which range ("weight amp", "bias", "normalisation mean", "normalisation scale").
        what: &'static str,
        /// Lower end.
        lo: f32,
        /// Upper end.
        hi: f32,
    },
}

fn check_range(what: &'static str, r: &Range<f32>) -> Result<(), RandomMlpError> {
    if r.start.is_finite() && r.end.is_finite() && r.start < r.end {
        Ok(())
    } else {
        Err(RandomMlpError::Range {
            what,
            lo: r.start,
            hi: r.end,
        })
    }
}

/// Checks `sizes` against [`limits`] the way [`MlpWeights::validate`] does, before anything is drawn
/// or allocated (so absurd sizes fail fast instead of allocating).
fn check_sizes(sizes: &[usize]) -> Result<(), MlpShapeError> {
    use limits::*;
    let n = sizes.len().saturating_sub(1);
    if n == 0 {
        return Err(MlpShapeError::Empty);
    }
    if n - 1 > MAX_HIDDEN_LAYERS {
        return Err(MlpShapeError::TooDeep(n - 1));
    }
    for (k, &value) in sizes.iter().enumerate() {
        let (layer, what, max) = match k {
            0 => (0, "n_in", MAX_INPUTS),
            k if k == n => (k - 1, "n_out", MAX_OUTPUTS),
            k => (k - 1, "n_out", MAX_WIDTH),
        };
        if value == 0 || value > max {
            return Err(MlpShapeError::Dimension {
                layer,
                what,
                value,
                max,
            });
        }
    }
    Ok(())
}

/// A reproducible random ReLU MLP: `spec.sizes`, hidden layers ReLU and a linear output, weights,
/// biases and normalisation drawn as `spec` says from a ChaCha8 stream seeded with `seed`.
///
/// Draw order (part of the contract, so a seed keeps meaning the same network): for each layer its
/// weights (row-major `[n_out][n_in]`) then its biases; then all normalisation means, then all scales.
/// The result passes [`MlpWeights::validate`].
///
/// # Errors
/// [`RandomMlpError::Shape`] if the sizes break [`limits`] (fewer than two sizes, a zero or too-large
/// dimension, too many hidden layers), [`RandomMlpError::Range`] for an empty or non-finite range.
pub fn seeded_mlp(spec: &RandomMlpSpec, seed: u64) -> Result<MlpWeights, RandomMlpError> {
    let sizes = &spec.sizes;
    check_sizes(sizes)?;
    if let WeightInit::Uniform { amp } = spec.weights {
        check_range("weight amp", &(-amp..amp))?;
    }
    check_range("bias", &spec.bias)?;
    if let NormInit::Uniform { mean, scale } = &spec.norm {
        check_range("normalisation mean", mean)?;
        check_range("normalisation scale", scale)?;
    }

    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = sizes.len() - 1;
    let layers = sizes
        .windows(2)
        .enumerate()
        .map(|(k, w)| {
            let (n_in, n_out) = (w[0], w[1]);
            let amp = match spec.weights {
                WeightInit::Uniform { amp } => amp,
                WeightInit::HeUniform => (6.0 / n_in as f32).sqrt(),
            };
            DenseLayer {
                n_in,
                n_out,
                weight: (0..n_in * n_out)
                    .map(|_| rng.random_range(-amp..amp))
                    .collect(),
                bias: (0..n_out)
                    .map(|_| rng.random_range(spec.bias.clone()))
                    .collect(),
                activation: if k + 1 == n {
                    Activation::Identity
                } else {
                    Activation::Relu
                },
            }
        })
        .collect();
    let n_in = sizes[0];
    let norm = match &spec.norm {
        NormInit::Identity => Normalisation::identity(n_in),
        NormInit::Uniform { mean, scale } => Normalisation {
            mean: (0..n_in).map(|_| rng.random_range(mean.clone())).collect(),
            scale: (0..n_in).map(|_| rng.random_range(scale.clone())).collect(),
        },
    };
    let w = MlpWeights { norm, layers };
    w.validate()?;
    Ok(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(sizes: &[usize]) -> RandomMlpSpec {
        RandomMlpSpec::new(sizes)
    }

    #[test]
    fn same_seed_same_weights_other_seed_differs() {
        let s = spec(&[6, 9, 4, 1]);
        let a = seeded_mlp(&s, 42).unwrap();
        let b = seeded_mlp(&s, 42).unwrap();
        let c = seeded_mlp(&s, 43).unwrap();
        assert_eq!(a, b);
        assert_ne!(a.layers[0].weight, c.layers[0].weight);
        assert_ne!(a.norm, c.norm);
    }

    #[test]
    fn shapes_activations_and_ranges_are_as_asked() {
        for sizes in [
            vec![1usize, 1],
            vec![40, 268, 215, 1],
            vec![5, 3, 7, 2, 4, 1],
        ] {
            let s = spec(&sizes);
            let w = seeded_mlp(&s, 1).unwrap();
            assert_eq!(w.sizes(), sizes);
            let n = w.layers.len();
            for (k, l) in w.layers.iter().enumerate() {
                assert_eq!(l.weight.len(), sizes[k] * sizes[k + 1]);
                assert_eq!(l.bias.len(), sizes[k + 1]);
                let want = if k + 1 == n {
                    Activation::Identity
                } else {
                    Activation::Relu
                };
                assert_eq!(l.activation, want, "layer {k}");
                assert!(l.weight.iter().all(|v| (-0.5..0.5).contains(v)));
                assert!(l.bias.iter().all(|v| (-0.1..0.1).contains(v)));
            }
            assert!(w.norm.mean.iter().all(|v| (-2.0..2.0).contains(v)));
            assert!(w.norm.scale.iter().all(|v| (0.1..3.0).contains(v)));
        }
    }

    #[test]
    fn he_uniform_and_identity_norm() {
        let s = RandomMlpSpec {
            sizes: vec![24, 96, 1],
            weights: WeightInit::HeUniform,
            bias: -0.1..0.1,
            norm: NormInit::Identity,
        };
        let w = seeded_mlp(&s, 5).unwrap();
        assert_eq!(w.norm, Normalisation::identity(24));
        for l in &w.layers {
            let lim = (6.0 / l.n_in as f32).sqrt();
            assert!(l.weight.iter().all(|v| v.abs() <= lim));
            // The draws use the interval, not a corner of it.
            let max = l.weight.iter().fold(0f32, |m, v| m.max(v.abs()));
            assert!(max > 0.5 * lim, "layer max |w| {max} vs limit {lim}");
        }
    }

    #[test]
    fn bad_sizes_and_ranges_are_errors() {
        let err = |sizes: &[usize]| seeded_mlp(&spec(sizes), 0).unwrap_err();
        assert_eq!(err(&[4]), RandomMlpError::Shape(MlpShapeError::Empty));
        assert_eq!(err(&[]), RandomMlpError::Shape(MlpShapeError::Empty));
        assert!(matches!(
            err(&[4, 0, 1]),
            RandomMlpError::Shape(MlpShapeError::Dimension { layer: 0, .. })
        ));
        assert!(matches!(
            err(&[4, 3, 2]),
            RandomMlpError::Shape(MlpShapeError::Dimension { layer: 1, .. })
        ));
        assert!(matches!(
            err(&[usize::MAX, 1]),
            RandomMlpError::Shape(MlpShapeError::Dimension { what: "n_in", .. })
        ));
        assert!(matches!(
            err(&[2, 2, 2, 2, 2, 2, 1]),
            RandomMlpError::Shape(MlpShapeError::TooDeep(5))
        ));
        let mut s = spec(&[3, 1]);
        s.bias = 0.3..-0.1; // reversed
        assert!(matches!(
            seeded_mlp(&s, 0),
            Err(RandomMlpError::Range { what: "bias", .. })
        ));
        s.bias = 0.0..0.1;
        s.weights = WeightInit::Uniform { amp: f32::NAN };
        assert!(matches!(
            seeded_mlp(&s, 0),
            Err(RandomMlpError::Range {
                what: "weight amp",
                ..
            })
        ));
    }
}

//! The plain description of a trained MLP friction network, as a trainer or an importer produces it.
//!
//! Weights are stored in **PyTorch order**: each dense layer's weight is row-major `[n_out][n_in]`
//! (`nn.Linear.weight`), followed by its bias `[n_out]`. Inputs are raw (un-normalised) feature vectors;
//! the network first applies `x_norm = (x − mean) / scale` per input (the authors' mean/IQR scaler).
//! The output is joint-side friction in Nm.
//!
//! This type owns heap memory and is meant for loading, training and export. The real-time path uses
//! [`crate::kernel::Mlp`], built once from it.

use thiserror::Error;

/// Shape limits every model must satisfy (checked by the weight reader and the kernel builder).
pub mod limits {
    /// Largest number of inputs.
    pub const MAX_INPUTS: usize = 1024;
    /// Largest hidden-layer width.
    pub const MAX_WIDTH: usize = 1024;
    /// Largest number of hidden layers (the output layer comes on top).
    pub const MAX_HIDDEN_LAYERS: usize = 4;
    /// Largest number of outputs (friction networks have one).
    pub const MAX_OUTPUTS: usize = 1;
}

/// Activation applied after a dense layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// max(0, x)
    Relu,
    /// x (the linear output layer)
    Identity,
}

/// One dense layer `y = act(W·x + b)`.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseLayer {
    /// Inputs of this layer.
    pub n_in: usize,
    /// Outputs of this layer.
    pub n_out: usize,
    /// Row-major `[n_out][n_in]` (PyTorch `nn.Linear.weight`).
    pub weight: Vec<f32>,
    /// `[n_out]`.
    pub bias: Vec<f32>,
    /// Activation after the affine map.
    pub activation: Activation,
}

/// How weights are stored in a file and in the kernel (computation is always f32).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StorageDtype {
    /// IEEE binary32.
    F32,
    /// IEEE binary16 (decoded to f32 inside the kernel).
    F16,
    /// bfloat16 (decoded to f32 inside the kernel).
    Bf16,
    /// Symmetric int8 hidden-layer weights with one f32 scale per output channel (zero-point 0):
    /// `w ≈ q · scale[o]`, `q ∈ [−127, 127]`. Biases, the output layer and the normalisation stay f32.
    /// Decoded to f32 inside the kernel, or multiplied as int8 × u8 activations with `vpdpbusd`
    /// ([`crate::kernel::KernelPath::Avx512Vnni`]).
    Int8,
    /// Symmetric 14-bit fixed point in int16 hidden-layer weights with one f32 scale per output
    /// channel: `w ≈ q · scale[o]`, `q ∈ [−8191, 8191]`; biases, the output layer and the
    /// normalisation stay f32. Every kernel path multiplies them with per-call int16 activations
    /// (`|a| ≤ 16383`) in exact i32 arithmetic (`vpdpwssd` on AVX-512 VNNI, `vpmaddwd` elsewhere), so
    /// all paths give bit-identical outputs ([`crate::kernel`], "int16").
    Int16,
}

impl StorageDtype {
    /// All storage dtypes, widest first.
    pub const ALL: [StorageDtype; 5] = [
        StorageDtype::F32,
        StorageDtype::F16,
        StorageDtype::Bf16,
        StorageDtype::Int16,
        StorageDtype::Int8,
    ];

    /// Bytes per stored weight (for [`StorageDtype::Int8`] and [`StorageDtype::Int16`]: per
    /// hidden-layer weight; their scales, biases and output layer are f32).
    pub fn size_bytes(self) -> usize {
        match self {
            StorageDtype::F32 => 4,
            StorageDtype::F16 | StorageDtype::Bf16 | StorageDtype::Int16 => 2,
            StorageDtype::Int8 => 1,
        }
    }

    /// Short lowercase name (`f32`, `f16`, `bf16`, `int16`, `int8`), the spelling the tools print and
    /// parse.
    pub fn name(self) -> &'static str {
        match self {
            StorageDtype::F32 => "f32",
            StorageDtype::F16 => "f16",
            StorageDtype::Bf16 => "bf16",
            StorageDtype::Int8 => "int8",
            StorageDtype::Int16 => "int16",
        }
    }
}

/// Per-input affine normalisation `x_norm = (x − mean) / scale`.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalisation {
    /// Per-input mean (raw units).
    pub mean: Vec<f32>,
    /// Per-input scale (raw units; the authors use the inter-quartile range). Never zero.
    pub scale: Vec<f32>,
}

impl Normalisation {
    /// The identity normalisation for `n` inputs.
    pub fn identity(n: usize) -> Self {
        Self {
            mean: vec![0.0; n],
            scale: vec![1.0; n],
        }
    }
}

/// A complete MLP: normalisation, hidden ReLU layers, linear output.
#[derive(Clone, Debug, PartialEq)]
pub struct MlpWeights {
    /// Input normalisation (length = inputs of the first layer).
    pub norm: Normalisation,
    /// Dense layers, first to last. The last one is the output layer.
    pub layers: Vec<DenseLayer>,
}

/// Why an MLP description is not acceptable.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MlpShapeError {
    /// No layers at all.
    #[error("the network has no layers")]
    Empty,
    /// Too many hidden layers.
    #[error("{0} hidden layers, at most {max} are supported", max = limits::MAX_HIDDEN_LAYERS)]
    TooDeep(usize),
    /// A dimension is zero or over its limit.
    #[error("layer {layer}: {what} = {value} is outside 1..={max}")]
    Dimension {
        /// Layer index (0-based).
        layer: usize,
        /// Which dimension.
        what: &'static str,
        /// Its value.
        value: usize,
        /// The limit.
        max: usize,
    },
    /// Consecutive layers do not chain.
    #[error("layer {layer} expects {expected} inputs but the previous layer gives {got}")]
    Chain {
        /// Layer index.
        layer: usize,
        /// Inputs expected by this layer.
        expected: usize,
        /// Outputs of the previous stage.
        got: usize,
    },
    /// A buffer has the wrong length.
    #[error("layer {layer}: {what} has {got} values, expected {expected}")]
    Length {
        /// Layer index (or usize::MAX for the normalisation).
        layer: usize,
        /// Which buffer.
        what: &'static str,
        /// Found.
        got: usize,
        /// Expected.
        expected: usize,
    },
    /// A value is NaN or infinite, or a scale is zero.
    #[error("{what}[{index}] = {value} is not a finite{nonzero} number")]
    NonFinite {
        /// Which buffer (e.g. "layer 1 weight", "normalisation scale").
        what: String,
        /// Flat index.
        index: usize,
        /// The value.
        value: f32,
        /// " non-zero" for scales.
        nonzero: &'static str,
    },
    /// Hidden layers must be ReLU and the output layer linear.
    #[error(
        "layer {layer}: activation {found:?} not supported here (hidden layers ReLU, output identity)"
    )]
    Activation {
        /// Layer index.
        layer: usize,
        /// Found.
        found: Activation,
    },
}

impl MlpWeights {
    /// Number of raw inputs.
    pub fn n_inputs(&self) -> usize {
        self.layers.first().map_or(0, |l| l.n_in)
    }
    /// Number of outputs.
    pub fn n_outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.n_out)
    }
    /// Layer sizes including input and output, e.g. `[40, 268, 215, 1]`.
    pub fn sizes(&self) -> Vec<usize> {
        let mut v = vec![self.n_inputs()];
        v.extend(self.layers.iter().map(|l| l.n_out));
        v
    }
    /// Multiply–accumulate operations per inference (normalisation excluded).
    pub fn macs(&self) -> usize {
        self.layers.iter().map(|l| l.n_in * l.n_out).sum()
    }
    /// Number of stored parameters (weights + biases, normalisation excluded).
    pub fn n_params(&self) -> usize {
        self.layers.iter().map(|l| l.n_in * l.n_out + l.n_out).sum()
    }

    /// Checks shapes against [`limits`], chaining, buffer lengths, finiteness and activations.
    pub fn validate(&self) -> Result<(), MlpShapeError> {
        use limits::*;
        let n = self.layers.len();
        if n == 0 {
            return Err(MlpShapeError::Empty);
        }
        if n - 1 > MAX_HIDDEN_LAYERS {
            return Err(MlpShapeError::TooDeep(n - 1));
        }
        let dim = |layer, what, value, max| {
            if value == 0 || value > max {
                Err(MlpShapeError::Dimension {
                    layer,
                    what,
                    value,
                    max,
                })
            } else {
                Ok(())
            }
        };
        dim(0, "n_in", self.n_inputs(), MAX_INPUTS)?;
        for (k, l) in self.layers.iter().enumerate() {
            let max_out = if k + 1 == n { MAX_OUTPUTS } else { MAX_WIDTH };
            dim(k, "n_out", l.n_out, max_out)?;
            if k > 0 && l.n_in != self.layers[k - 1].n_out {
                return Err(MlpShapeError::Chain {
                    layer: k,
                    expected: l.n_in,
                    got: self.layers[k - 1].n_out,
                });
            }
            let want_act = if k + 1 == n {
                Activation::Identity
            } else {
                Activation::Relu
            };
            if l.activation != want_act {
                return Err(MlpShapeError::Activation {
                    layer: k,
                    found: l.activation,
                });
            }
            if l.weight.len() != l.n_in * l.n_out {
                return Err(MlpShapeError::Length {
                    layer: k,
                    what: "weight",
                    got: l.weight.len(),
                    expected: l.n_in * l.n_out,
                });
            }
            if l.bias.len() != l.n_out {
                return Err(MlpShapeError::Length {
                    layer: k,
                    what: "bias",
                    got: l.bias.len(),
                    expected: l.n_out,
                });
            }
            check_finite(&format!("layer {k} weight"), &l.weight, false)?;
            check_finite(&format!("layer {k} bias"), &l.bias, false)?;
        }
        let ni = self.n_inputs();
        for (what, v) in [("mean", &self.norm.mean), ("scale", &self.norm.scale)] {
            if v.len() != ni {
                return Err(MlpShapeError::Length {
                    layer: usize::MAX,
                    what,
                    got: v.len(),
                    expected: ni,
                });
            }
        }
        check_finite("normalisation mean", &self.norm.mean, false)?;
        check_finite("normalisation scale", &self.norm.scale, true)?;
        Ok(())
    }

    /// Reference forward pass in f64 accumulation, straightforward loops. Slow; for tests and tools.
    pub fn forward_reference(&self, x: &[f32]) -> Vec<f32> {
        let mut a: Vec<f64> = x
            .iter()
            .zip(self.norm.mean.iter().zip(&self.norm.scale))
            .map(|(&x, (&m, &s))| (x as f64 - m as f64) / s as f64)
            .collect();
        for l in &self.layers {
            let mut y = vec![0f64; l.n_out];
            for (o, yo) in y.iter_mut().enumerate() {
                let row = &l.weight[o * l.n_in..(o + 1) * l.n_in];
                let mut acc = l.bias[o] as f64;
                for (w, xi) in row.iter().zip(&a) {
                    acc += *w as f64 * xi;
                }
                *yo = match l.activation {
                    Activation::Relu => acc.max(0.0),
                    Activation::Identity => acc,
                };
            }
            a = y;
        }
        a.into_iter().map(|v| v as f32).collect()
    }
}

fn check_finite(what: &str, v: &[f32], nonzero: bool) -> Result<(), MlpShapeError> {
    for (index, &value) in v.iter().enumerate() {
        if !value.is_finite() || (nonzero && value == 0.0) {
            return Err(MlpShapeError::NonFinite {
                what: what.to_string(),
                index,
                value,
                nonzero: if nonzero { " non-zero" } else { "" },
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> MlpWeights {
        MlpWeights {
            norm: Normalisation {
                mean: vec![1.0, 0.0],
                scale: vec![2.0, 1.0],
            },
            layers: vec![
                DenseLayer {
                    n_in: 2,
                    n_out: 2,
                    weight: vec![1.0, 0.0, 0.0, -1.0],
                    bias: vec![0.0, 0.5],
                    activation: Activation::Relu,
                },
                DenseLayer {
                    n_in: 2,
                    n_out: 1,
                    weight: vec![1.0, 2.0],
                    bias: vec![0.25],
                    activation: Activation::Identity,
                },
            ],
        }
    }

    #[test]
    fn reference_forward_by_hand() {
        // x = [3, -1] → norm [1, -1] → layer1 relu([1, 1.5]) → 1 + 3 + 0.25
        let y = tiny().forward_reference(&[3.0, -1.0]);
        assert_eq!(y, vec![4.25]);
        assert_eq!(tiny().sizes(), vec![2, 2, 1]);
        tiny().validate().unwrap();
    }

    #[test]
    fn validate_rejects_bad_shapes() {
        let mut m = tiny();
        m.layers[0].weight.pop();
        assert!(matches!(m.validate(), Err(MlpShapeError::Length { .. })));
        let mut m = tiny();
        m.norm.scale[1] = 0.0;
        assert!(matches!(m.validate(), Err(MlpShapeError::NonFinite { .. })));
        let mut m = tiny();
        m.layers[1].weight[0] = f32::NAN;
        assert!(matches!(m.validate(), Err(MlpShapeError::NonFinite { .. })));
        let mut m = tiny();
        m.layers[1].activation = Activation::Relu;
        assert!(matches!(
            m.validate(),
            Err(MlpShapeError::Activation { .. })
        ));
    }
}

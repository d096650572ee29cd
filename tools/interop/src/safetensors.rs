//! safetensors import and export of friction MLPs as PyTorch `nn.Sequential` state dicts.
//!
//! **What we write** ([`export_bytes`]): for an MLP with layers `0 … L−1`,
//! - `"{2k}.weight"` float32 `[n_out, n_in]` and `"{2k}.bias"` float32 `[n_out]` for layer k, i.e. the
//!   state dict of `nn.Sequential(Linear, ReLU, Linear, ReLU, …, Linear)` (Linear at even indices);
//! - `"norm.mean"` and `"norm.scale"` float32 `[n_in]`: the input normalisation
//!   `x_norm = (x − mean) / scale` applied before layer 0 (identity: zeros and ones). PyTorch's
//!   `load_state_dict` needs `strict=False` (or popping these two keys) to load the file into the plain
//!   `nn.Sequential`;
//! - `__metadata__`: `"format": "pt"`, `"frictionless.layout"` (a one-line description of the above)
//!   and the [`super::ModelHints`] keys (`frictionless.joint_name`, `…gear_ratio`, `…kt_nm_per_a`,
//!   `…features`, `…history`, `…temperature`).
//!
//! **What we read** ([`import_bytes`]): tensors named `[prefix.]<index>.weight` / `.bias` (one common
//! prefix, e.g. `net.`), with Linear indices evenly spaced by 2 (`Linear,ReLU,…`: 0,2,4) or by 3
//! (`Linear,ReLU,Dropout,…`: 0,3,6), starting at 0. A missing bias is zero. Weights must be PyTorch
//! layout `[out, in]` (checked by chaining, which catches transposes of non-square layers). Tensors may
//! be F32, F64, F16 or BF16 (converted to f32). The normalisation comes from `[prefix.]norm.mean` /
//! `norm.scale` tensors, else from metadata keys `norm.mean` / `norm.scale` (or
//! `frictionless.norm.mean` / `…scale`) holding JSON arrays, else it is the identity. Other tensors
//! (e.g. physics parameters of a PINN) are listed in [`SafetensorsImport::ignored`].
//!
//! Not here: ReLU/Dropout positions cannot be verified from a state dict (they have no parameters);
//! hidden layers are assumed ReLU and the last layer linear, as every friction MLP here is.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use frictionless::mlp::{Activation, DenseLayer, MlpShapeError, MlpWeights, Normalisation};
use safetensors::tensor::{Dtype, SafeTensors, TensorView};
use thiserror::Error;

/// Why a safetensors file cannot be imported or a model cannot be exported.
#[derive(Debug, Error)]
pub enum SafetensorsError {
    /// The bytes are not a safetensors file.
    #[error("not a safetensors file: {0}")]
    Decode(String),
    /// No `<index>.weight` tensors.
    #[error(
        "no Linear layers found (expected tensors named `0.weight`, `0.bias`, `2.weight`, …); tensors present: {0}"
    )]
    NoLayers(String),
    /// Layer tensors use different prefixes.
    #[error("layer tensors use different prefixes (`{0}` and `{1}`)")]
    MixedPrefix(String, String),
    /// Layer indices are not 0, s, 2s, … with s = 2 or 3.
    #[error(
        "Linear indices {0:?} are not 0, s, 2s, … with s = 2 (Linear,ReLU,…) or s = 3 (Linear,ReLU,Dropout,…)"
    )]
    Spacing(Vec<usize>),
    /// A tensor has an unusable dtype or shape.
    #[error("tensor `{name}`: {reason}")]
    Tensor {
        /// Tensor name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A metadata value is malformed.
    #[error("metadata key `{key}`: {reason}")]
    Metadata {
        /// The key.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// The resulting network violates the MLP shape rules.
    #[error("network: {0}")]
    Shape(#[from] MlpShapeError),
    /// Encoding failed.
    #[error("safetensors encode failed: {0}")]
    Encode(String),
    /// Reading a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// An error in a named file.
    #[error("{path}: {source}")]
    InFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: Box<SafetensorsError>,
    },
}

/// Where the imported normalisation came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormSource {
    /// `norm.mean` / `norm.scale` tensors.
    Tensors,
    /// `norm.mean` / `norm.scale` metadata (JSON arrays).
    Metadata,
    /// None found: identity.
    Identity,
}

/// An imported state dict.
#[derive(Clone, Debug, PartialEq)]
pub struct SafetensorsImport {
    /// The network.
    pub mlp: MlpWeights,
    /// Index spacing of the Linear layers (2 or 3; 0 for a single layer).
    pub spacing: usize,
    /// Common prefix of the layer tensors (e.g. `"net."`, or empty).
    pub prefix: String,
    /// Where the normalisation came from.
    pub norm_source: NormSource,
    /// Tensors that are not part of the MLP.
    pub ignored: Vec<String>,
    /// The `__metadata__` map.
    pub metadata: BTreeMap<String, String>,
}

/// Imports a safetensors file; every error names `path`.
pub fn import_file(path: &Path) -> Result<SafetensorsImport, SafetensorsError> {
    let bytes =
        frictionless::regular_file::read(path, crate::MAX_IMPORT_BYTES).map_err(|source| {
            SafetensorsError::Io {
                path: path.to_owned(),
                source,
            }
        })?;
    import_bytes(&bytes).map_err(|e| SafetensorsError::InFile {
        path: path.to_owned(),
        source: Box::new(e),
    })
}

/// Decodes one tensor to f32 values.
fn to_f32(name: &str, t: &TensorView<'_>) -> Result<Vec<f32>, SafetensorsError> {
    let d = t.data();
    let v: Vec<f32> = match t.dtype() {
        Dtype::F32 => d
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect(),
        Dtype::F64 => d
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])) as f32)
            .collect(),
        Dtype::F16 => d
            .chunks_exact(2)
            .map(|c| half::f16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect(),
        Dtype::BF16 => d
            .chunks_exact(2)
            .map(|c| half::bf16::from_le_bytes([c[0], c[1]]).to_f32())
            .collect(),
        other => {
            return Err(SafetensorsError::Tensor {
                name: name.to_string(),
                reason: format!("dtype {other:?} is not supported (F32, F64, F16, BF16)"),
            });
        }
    };
    Ok(v)
}

/// Splits `prefix.<index>.weight|bias` into (prefix, index, is_weight).
fn layer_name(name: &str) -> Option<(&str, usize, bool)> {
    let (rest, is_weight) = if let Some(r) = name.strip_suffix(".weight") {
        (r, true)
    } else {
        (name.strip_suffix(".bias")?, false)
    };
    let (prefix, idx) = match rest.rfind('.') {
        Some(p) => (&rest[..=p], &rest[p + 1..]),
        None => ("", rest),
    };
    if idx.is_empty() || !idx.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((prefix, idx.parse().ok()?, is_weight))
}

fn metadata_vec(
    meta: &BTreeMap<String, String>,
    key: &str,
) -> Result<Option<Vec<f32>>, SafetensorsError> {
    for k in [key.to_string(), format!("{}{key}", super::META_PREFIX)] {
        if let Some(v) = meta.get(&k) {
            let parsed: Vec<f32> =
                serde_json::from_str(v).map_err(|e| SafetensorsError::Metadata {
                    key: k.clone(),
                    reason: format!("not a JSON array of numbers: {e}"),
                })?;
            return Ok(Some(parsed));
        }
    }
    Ok(None)
}

/// The tensors of a state dict sorted by role: layer weights and biases by index, everything else.
struct Grouped<'a> {
    /// The common prefix of the layer tensors (e.g. `net.`), empty if none.
    prefix: String,
    weights: BTreeMap<usize, (String, TensorView<'a>)>,
    biases: HashMap<usize, (String, TensorView<'a>)>,
    others: Vec<(String, TensorView<'a>)>,
}

/// Imports a PyTorch `nn.Sequential` state dict from safetensors bytes.
pub fn import_bytes(bytes: &[u8]) -> Result<SafetensorsImport, SafetensorsError> {
    let st =
        SafeTensors::deserialize(bytes).map_err(|e| SafetensorsError::Decode(e.to_string()))?;
    let (_, header) =
        SafeTensors::read_metadata(bytes).map_err(|e| SafetensorsError::Decode(e.to_string()))?;
    let metadata: BTreeMap<String, String> = header
        .metadata()
        .as_ref()
        .map(|m| m.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
        .unwrap_or_default();

    let Grouped {
        prefix,
        weights,
        biases,
        others,
    } = group_tensors(&st)?;
    let spacing = check_spacing(&weights)?;
    let layers = dense_layers(&weights, &biases)?;
    let n_in = layers[0].n_in;
    let (norm, norm_source, ignored) = read_normalisation(&others, &prefix, n_in, &metadata)?;
    let mlp = MlpWeights { norm, layers };
    mlp.validate()?;
    Ok(SafetensorsImport {
        mlp,
        spacing,
        prefix,
        norm_source,
        ignored,
        metadata,
    })
}

/// Sorts the tensors into layer weights, layer biases (`prefix.<index>.weight|bias`, one prefix for
/// all) and others; fails if there is no layer weight or a bias has no weight.
fn group_tensors<'a>(st: &SafeTensors<'a>) -> Result<Grouped<'a>, SafetensorsError> {
    let mut prefix: Option<&str> = None;
    let mut weights: BTreeMap<usize, (String, TensorView<'a>)> = BTreeMap::new();
    let mut biases: HashMap<usize, (String, TensorView<'a>)> = HashMap::new();
    let mut others: Vec<(String, TensorView<'a>)> = Vec::new();
    let mut all_names: Vec<String> = Vec::new();
    for (name, view) in st.iter() {
        all_names.push(name.to_string());
        match layer_name(name) {
            Some((p, idx, is_weight)) => {
                match prefix {
                    None => prefix = Some(p),
                    Some(q) if q != p => {
                        return Err(SafetensorsError::MixedPrefix(q.to_string(), p.to_string()));
                    }
                    _ => {}
                }
                let slot = (name.to_string(), view);
                if is_weight {
                    weights.insert(idx, slot);
                } else {
                    biases.insert(idx, slot);
                }
            }
            None => others.push((name.to_string(), view)),
        }
    }
    all_names.sort();
    let prefix = prefix.unwrap_or("").to_string();
    if weights.is_empty() {
        return Err(SafetensorsError::NoLayers(all_names.join(", ")));
    }
    if let Some((&idx, (name, _))) = biases.iter().find(|(i, _)| !weights.contains_key(i)) {
        return Err(SafetensorsError::Tensor {
            name: name.clone(),
            reason: format!("bias of layer index {idx} has no matching weight"),
        });
    }
    Ok(Grouped {
        prefix,
        weights,
        biases,
        others,
    })
}

/// The layer indices start at 0 and are evenly spaced by 2 or 3; returns the spacing (0 for a
/// single layer). `weights` is not empty.
fn check_spacing<T>(weights: &BTreeMap<usize, T>) -> Result<usize, SafetensorsError> {
    let indices: Vec<usize> = weights.keys().copied().collect();
    let spacing = if indices.len() > 1 {
        indices[1] - indices[0]
    } else {
        0
    };
    let even = indices.iter().enumerate().all(|(k, &i)| i == k * spacing);
    if indices[0] != 0 || (indices.len() > 1 && (!(2..=3).contains(&spacing) || !even)) {
        return Err(SafetensorsError::Spacing(indices));
    }
    Ok(spacing)
}

/// The dense layers in index order, shapes checked to chain (`[out, in]`, PyTorch layout); Relu
/// after every layer but the last.
fn dense_layers(
    weights: &BTreeMap<usize, (String, TensorView<'_>)>,
    biases: &HashMap<usize, (String, TensorView<'_>)>,
) -> Result<Vec<DenseLayer>, SafetensorsError> {
    let mut layers = Vec::with_capacity(weights.len());
    let n_layers = weights.len();
    for (k, (idx, (wname, wview))) in weights.iter().enumerate() {
        let shape = wview.shape();
        if shape.len() != 2 {
            return Err(SafetensorsError::Tensor {
                name: wname.clone(),
                reason: format!("shape {shape:?} is not 2-D [out, in]"),
            });
        }
        let (n_out, n_in) = (shape[0], shape[1]);
        if let Some(prev) = layers.last().map(|l: &DenseLayer| l.n_out)
            && prev != n_in
        {
            return Err(SafetensorsError::Tensor {
                name: wname.clone(),
                reason: format!(
                    "shape {shape:?} does not take the previous layer's {prev} outputs (PyTorch layout is [out, in]; transposed?)"
                ),
            });
        }
        let weight = to_f32(wname, wview)?;
        let bias = match biases.get(idx) {
            Some((bname, bview)) => {
                if bview.shape() != [n_out] {
                    return Err(SafetensorsError::Tensor {
                        name: bname.clone(),
                        reason: format!("shape {:?}, expected [{n_out}]", bview.shape()),
                    });
                }
                to_f32(bname, bview)?
            }
            None => vec![0.0; n_out],
        };
        layers.push(DenseLayer {
            n_in,
            n_out,
            weight,
            bias,
            activation: if k + 1 == n_layers {
                Activation::Identity
            } else {
                Activation::Relu
            },
        });
    }
    Ok(layers)
}

/// The input normalisation: `norm.mean`/`norm.scale` tensors first, then metadata, else the
/// identity. Also returns the names of the other tensors (ignored), sorted.
fn read_normalisation(
    others: &[(String, TensorView<'_>)],
    prefix: &str,
    n_in: usize,
    metadata: &BTreeMap<String, String>,
) -> Result<(Normalisation, NormSource, Vec<String>), SafetensorsError> {
    let mut ignored = Vec::new();
    let mut mean_t = None;
    let mut scale_t = None;
    for (name, view) in others {
        let bare = name.strip_prefix(prefix).unwrap_or(name);
        let slot = match bare {
            "norm.mean" => &mut mean_t,
            "norm.scale" => &mut scale_t,
            _ => {
                ignored.push(name.clone());
                continue;
            }
        };
        if view.shape() != [n_in] {
            return Err(SafetensorsError::Tensor {
                name: name.clone(),
                reason: format!(
                    "shape {:?}, expected [{n_in}] (one per input)",
                    view.shape()
                ),
            });
        }
        *slot = Some(to_f32(name, view)?);
    }
    ignored.sort();
    let (norm, norm_source) = match (mean_t, scale_t) {
        (Some(mean), Some(scale)) => (Normalisation { mean, scale }, NormSource::Tensors),
        (None, None) => match (
            metadata_vec(metadata, "norm.mean")?,
            metadata_vec(metadata, "norm.scale")?,
        ) {
            (Some(mean), Some(scale)) => (Normalisation { mean, scale }, NormSource::Metadata),
            (None, None) => (Normalisation::identity(n_in), NormSource::Identity),
            _ => {
                return Err(SafetensorsError::Metadata {
                    key: "norm.mean/norm.scale".into(),
                    reason: "only one of the two is present".into(),
                });
            }
        },
        _ => {
            return Err(SafetensorsError::Tensor {
                name: format!("{prefix}norm.mean/{prefix}norm.scale"),
                reason: "only one of the two is present".into(),
            });
        }
    };
    Ok((norm, norm_source, ignored))
}

/// The layout description written to `frictionless.layout`.
pub const LAYOUT_NOTE: &str = "nn.Sequential(Linear, ReLU, Linear, ReLU, ..., Linear): tensors {2k}.weight [out, in], {2k}.bias [out]; norm.mean/norm.scale [n_in]: x_norm = (x - mean) / scale before layer 0; output: joint-side friction torque [Nm]";

/// Serialises `mlp` as a safetensors state dict (see the module doc), with `metadata` added to
/// `__metadata__`.
pub fn export_bytes(
    mlp: &MlpWeights,
    metadata: &[(String, String)],
) -> Result<Vec<u8>, SafetensorsError> {
    mlp.validate()?;
    let le = |v: &[f32]| -> Vec<u8> { v.iter().flat_map(|x| x.to_le_bytes()).collect() };
    let n = mlp.n_inputs();
    let mut owned: Vec<(String, Vec<usize>, Vec<u8>)> = vec![
        ("norm.mean".into(), vec![n], le(&mlp.norm.mean)),
        ("norm.scale".into(), vec![n], le(&mlp.norm.scale)),
    ];
    for (k, l) in mlp.layers.iter().enumerate() {
        owned.push((
            format!("{}.weight", 2 * k),
            vec![l.n_out, l.n_in],
            le(&l.weight),
        ));
        owned.push((format!("{}.bias", 2 * k), vec![l.n_out], le(&l.bias)));
    }
    let mut views = Vec::with_capacity(owned.len());
    for (name, shape, data) in &owned {
        let v = TensorView::new(Dtype::F32, shape.clone(), data)
            .map_err(|e| SafetensorsError::Encode(e.to_string()))?;
        views.push((name.clone(), v));
    }
    let mut meta: HashMap<String, String> = HashMap::new();
    meta.insert("format".into(), "pt".into());
    meta.insert(format!("{}layout", super::META_PREFIX), LAYOUT_NOTE.into());
    for (k, v) in metadata {
        meta.insert(k.clone(), v.clone());
    }
    safetensors::tensor::serialize(views, Some(meta))
        .map_err(|e| SafetensorsError::Encode(e.to_string()))
}

//! ONNX import and export of friction MLPs.
//!
//! **Import** ([`import_bytes`], [`import_file`]) accepts what PyTorch's exporter writes for an
//! `nn.Sequential` of `Linear`/`ReLU` (opset ≥ 12, float32, one input `[batch, n]`, one output
//! `[batch, 1]`, any batch dimension):
//! - dense layers as `Gemm` (any `transB`, `alpha`, `beta`; `transA = 0`) or `MatMul` followed by an
//!   optional `Add`; weights from initializers (`raw_data` or `float_data`) or `Constant` nodes;
//! - `Relu` after every hidden layer; `Identity` and single-input `Dropout` pass through;
//! - element-wise `Sub`/`Add`/`Mul`/`Div` by a constant before the first layer (a normalisation),
//!   or right after a layer (folded into its rows);
//! - a leading n×n **diagonal** `Gemm` without `Relu` (the authors fold mean/IQR normalisation into it)
//!   becomes [`Normalisation`] with `scale_i = 1/w_ii`, `mean_i = −b_i·scale_i`; off-diagonal entries
//!   must be exactly 0 or below 1e-12 relative to the largest diagonal entry.
//!
//! Anything else (another op, a branch, two outputs, a non-float tensor, external data) is an
//! [`OnnxError`] naming the op type and node.
//!
//! **Export** ([`export_bytes`]) writes input `"input"` `[batch, n]`, output `"output"` `[batch, 1]`,
//! opset 13, IR 7: optional normalisation as `Sub`+`Div` or as a diagonal `Gemm` ([`NormExport`]),
//! then `Gemm(transB=1)`/`Relu` per layer, weights as little-endian `raw_data`, plus
//! [`super::ModelHints`] in `metadata_props`.
//!
//! Not here: inference (see `frictionless::kernel`), the `.fwt` codec, shape inference for arbitrary
//! graphs. Parsing uses the `onnx-protobuf` messages (protobuf 3); there is no hand-written decoder.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

use frictionless::mlp::{Activation, DenseLayer, MlpShapeError, MlpWeights, Normalisation};
use onnx_protobuf::attribute_proto::AttributeType;
use onnx_protobuf::tensor_proto::{DataLocation, DataType};
use onnx_protobuf::tensor_shape_proto::{Dimension, dimension};
use onnx_protobuf::{
    AttributeProto, GraphProto, Message, ModelProto, NodeProto, OperatorSetIdProto,
    StringStringEntryProto, TensorProto, TensorShapeProto, TypeProto, ValueInfoProto, type_proto,
};
use thiserror::Error;

/// Lowest default-domain opset accepted by the importer.
pub const MIN_OPSET: i64 = 12;
/// Opset written by the exporter.
pub const EXPORT_OPSET: i64 = 13;
/// Off-diagonal tolerance of the leading normalisation Gemm, relative to its largest diagonal entry.
pub const DIAGONAL_REL_TOL: f64 = 1e-12;

/// Why an ONNX file cannot be imported or a model cannot be exported.
#[derive(Debug, Error)]
pub enum OnnxError {
    /// The bytes are not an ONNX `ModelProto`.
    #[error("not an ONNX model (protobuf decode failed: {0})")]
    Decode(String),
    /// The model has no graph.
    #[error("ONNX model has no graph")]
    NoGraph,
    /// The default-domain opset is missing or too old.
    #[error("ONNX default-domain opset {found} is not supported (need >= {MIN_OPSET})")]
    Opset {
        /// Opset found (0 if none is declared).
        found: i64,
    },
    /// The graph has not exactly one (non-initializer) input.
    #[error("graph has {found} inputs ({names}); an MLP has exactly one")]
    InputCount {
        /// Number of inputs.
        found: usize,
        /// Their names.
        names: String,
    },
    /// The graph has not exactly one output.
    #[error("graph has {found} outputs ({names}); a friction MLP has exactly one")]
    OutputCount {
        /// Number of outputs.
        found: usize,
        /// Their names.
        names: String,
    },
    /// A graph input/output or tensor is not float32.
    #[error("{what} `{name}` has element type {elem_type}; only FLOAT (float32) is supported")]
    NonFloat {
        /// "graph input", "graph output" or "tensor".
        what: &'static str,
        /// Its name.
        name: String,
        /// The ONNX element type.
        elem_type: String,
    },
    /// A graph input/output shape is not `[batch, n]`.
    #[error("{what} `{name}`: {reason}")]
    BadShape {
        /// "graph input" or "graph output".
        what: &'static str,
        /// Its name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// An operator this importer does not support.
    #[error(
        "unsupported op `{op_type}` in node `{node}` (supported: Gemm, MatMul, Add, Sub, Mul, Div, Relu, Identity, Dropout, Constant)"
    )]
    UnsupportedOp {
        /// The op type.
        op_type: String,
        /// The node name (or `#index` when unnamed).
        node: String,
    },
    /// A supported op used in a way the importer cannot map to an MLP.
    #[error("node `{node}` ({op_type}): {reason}")]
    Node {
        /// The op type.
        op_type: String,
        /// The node name (or `#index` when unnamed).
        node: String,
        /// What is wrong.
        reason: String,
    },
    /// The graph is not one input→output chain.
    #[error("graph is not a single chain: {0}")]
    NotAChain(String),
    /// A weight tensor cannot be read.
    #[error("tensor `{name}`: {reason}")]
    Tensor {
        /// Tensor name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// The leading n×n linear layer (no ReLU) is not diagonal, so it is not a folded normalisation.
    #[error(
        "node `{node}`: leading {n}x{n} linear layer without Relu is not diagonal (w[{row}][{col}] = {value}), so it is not a folded normalisation"
    )]
    NotDiagonal {
        /// Node name.
        node: String,
        /// Width.
        n: usize,
        /// Row of the offending entry.
        row: usize,
        /// Column of the offending entry.
        col: usize,
        /// Its value.
        value: f64,
    },
    /// The resulting network violates the MLP shape rules.
    #[error("network: {0}")]
    Shape(#[from] MlpShapeError),
    /// Encoding the exported model failed.
    #[error("ONNX encode failed: {0}")]
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
        source: Box<OnnxError>,
    },
}

/// An imported ONNX model: the network plus what the graph says about itself.
#[derive(Clone, Debug, PartialEq)]
pub struct OnnxImport {
    /// The network (normalisation folded out of the graph).
    pub mlp: MlpWeights,
    /// Name of the graph input.
    pub input_name: String,
    /// Name of the graph output.
    pub output_name: String,
    /// Default-domain opset.
    pub opset: i64,
    /// ONNX IR version.
    pub ir_version: i64,
    /// `producer_name producer_version`, e.g. "pytorch 2.0.1".
    pub producer: String,
    /// Whether a normalisation (diagonal Gemm or element-wise ops) was found before the first layer.
    pub normalisation_found: bool,
    /// The batch dimension of the input: `None` if dynamic (a `dim_param` or unset), else its value.
    pub batch_dim: Option<i64>,
    /// The model's `metadata_props`.
    pub metadata: BTreeMap<String, String>,
}

/// How the exporter writes the normalisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum NormExport {
    /// `Sub(input, norm.mean)` then `Div(·, norm.scale)` — exact f32 statistics.
    #[default]
    SubDiv,
    /// One n×n diagonal `Gemm` with `w_ii = 1/scale_i`, `b_i = −mean_i/scale_i`, as the authors' exporter.
    DiagonalGemm,
}

/// Exporter options.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// Normalisation style (skipped entirely when the normalisation is the identity).
    pub norm: NormExport,
    /// Extra `metadata_props` (e.g. [`super::ModelHints::to_pairs`]).
    pub metadata: Vec<(String, String)>,
}

/// Imports an ONNX file; every error names `path`.
pub fn import_file(path: &Path) -> Result<OnnxImport, OnnxError> {
    let bytes =
        frictionless::regular_file::read(path, crate::MAX_IMPORT_BYTES).map_err(|source| {
            OnnxError::Io {
                path: path.to_owned(),
                source,
            }
        })?;
    import_bytes(&bytes).map_err(|e| OnnxError::InFile {
        path: path.to_owned(),
        source: Box::new(e),
    })
}

/// Imports an ONNX model from its serialized bytes.
pub fn import_bytes(bytes: &[u8]) -> Result<OnnxImport, OnnxError> {
    let model =
        ModelProto::parse_from_bytes(bytes).map_err(|e| OnnxError::Decode(e.to_string()))?;
    import_model(&model)
}

/// Imports an already decoded ONNX `ModelProto`.
pub fn import_model(model: &ModelProto) -> Result<OnnxImport, OnnxError> {
    let opset = model
        .opset_import
        .iter()
        .filter(|o| o.domain.is_empty() || o.domain == "ai.onnx")
        .map(|o| o.version)
        .max()
        .unwrap_or(0);
    if opset < MIN_OPSET {
        return Err(OnnxError::Opset { found: opset });
    }
    let graph = model.graph.as_ref().ok_or(OnnxError::NoGraph)?;
    let (consts, constant_nodes) = collect_constants(graph)?;
    let (input, output) = graph_io(graph, &consts)?;
    let (batch_dim, in_width) = io_shape(input, "graph input")?;
    io_shape(output, "graph output")?;

    let mut chain = Chain::new(in_width);
    walk(
        graph,
        &consts,
        &constant_nodes,
        &input.name,
        &output.name,
        &mut chain,
    )?;
    let (mlp, normalisation_found) = chain_to_mlp(chain)?;
    Ok(OnnxImport {
        mlp,
        input_name: input.name.clone(),
        output_name: output.name.clone(),
        opset,
        ir_version: model.ir_version,
        producer: format!("{} {}", model.producer_name, model.producer_version)
            .trim()
            .to_string(),
        normalisation_found,
        batch_dim,
        metadata: model
            .metadata_props
            .iter()
            .map(|p| (p.key.clone(), p.value.clone()))
            .collect(),
    })
}

/// The graph's constants by name (initializers and `Constant` node outputs), and the indices of the
/// `Constant` nodes.
fn collect_constants(
    graph: &GraphProto,
) -> Result<(HashMap<&str, &TensorProto>, HashSet<usize>), OnnxError> {
    let mut consts: HashMap<&str, &TensorProto> = graph
        .initializer
        .iter()
        .map(|t| (t.name.as_str(), t))
        .collect();
    if !graph.sparse_initializer.is_empty() {
        return Err(OnnxError::Tensor {
            name: "(sparse initializer)".into(),
            reason: "sparse initializers are not supported".into(),
        });
    }
    // Constant nodes are constants too.
    let mut constant_nodes = HashSet::new();
    for (k, node) in graph.node.iter().enumerate() {
        if node.op_type == "Constant" && node.domain.is_empty() {
            let t = node
                .attribute
                .iter()
                .find(|a| a.name == "value")
                .and_then(|a| a.t.as_ref())
                .ok_or_else(|| {
                    node_err(node, k, "only Constant with a `value` tensor is supported")
                })?;
            let out = node
                .output
                .first()
                .ok_or_else(|| node_err(node, k, "has no output"))?;
            consts.insert(out.as_str(), t);
            constant_nodes.insert(k);
        }
    }
    Ok((consts, constant_nodes))
}

/// The one real graph input (older exporters also list initializers as inputs) and the one output.
fn graph_io<'g>(
    graph: &'g GraphProto,
    consts: &HashMap<&str, &TensorProto>,
) -> Result<(&'g ValueInfoProto, &'g ValueInfoProto), OnnxError> {
    let inputs: Vec<&ValueInfoProto> = graph
        .input
        .iter()
        .filter(|i| !consts.contains_key(i.name.as_str()))
        .collect();
    if inputs.len() != 1 {
        return Err(OnnxError::InputCount {
            found: inputs.len(),
            names: names(inputs.iter().map(|i| i.name.as_str())),
        });
    }
    if graph.output.len() != 1 {
        return Err(OnnxError::OutputCount {
            found: graph.output.len(),
            names: names(graph.output.iter().map(|o| o.name.as_str())),
        });
    }
    Ok((inputs[0], &graph.output[0]))
}

/// Turns the walked chain into the network: folds a leading diagonal layer into the input affine
/// map, checks the Relu pattern, and reads the normalisation off the affine map. Returns the
/// network and whether a normalisation was found.
fn chain_to_mlp(chain: Chain) -> Result<(MlpWeights, bool), OnnxError> {
    let Chain {
        mut stages,
        input_affine,
        ..
    } = chain;
    if stages.is_empty() {
        return Err(OnnxError::NotAChain(
            "no dense layer (Gemm or MatMul) between input and output".into(),
        ));
    }
    let n_in = stages[0].n_in;
    let (mut a, mut c) = input_affine.unwrap_or_else(|| (vec![1.0; n_in], vec![0.0; n_in]));
    let mut normalisation_found = a.iter().any(|&v| v != 1.0) || c.iter().any(|&v| v != 0.0);

    // A leading linear n×n layer without ReLU followed by more layers: the folded normalisation.
    if stages.len() > 1 && !stages[0].relu {
        let s = stages.remove(0);
        let d = diagonal_of(&s)?;
        for i in 0..n_in {
            a[i] *= d[i];
            c[i] = d[i] * c[i] + s.bias[i];
        }
        normalisation_found = true;
    }
    check_relu_pattern(&stages)?;
    let norm = normalisation_from_affine(&a, &c)?;
    let last = stages.len() - 1;
    let layers = stages
        .iter()
        .enumerate()
        .map(|(k, s)| DenseLayer {
            n_in: s.n_in,
            n_out: s.n_out,
            weight: s.weight.iter().map(|&v| v as f32).collect(),
            bias: s.bias.iter().map(|&v| v as f32).collect(),
            activation: if k == last {
                Activation::Identity
            } else {
                Activation::Relu
            },
        })
        .collect();
    let mlp = MlpWeights { norm, layers };
    mlp.validate()?;
    Ok((mlp, normalisation_found))
}

/// Every dense layer but the last is followed by Relu; the last is not.
fn check_relu_pattern(stages: &[Stage]) -> Result<(), OnnxError> {
    let last = stages.len() - 1;
    for (k, s) in stages.iter().enumerate() {
        if k < last && !s.relu {
            return Err(OnnxError::Node {
                op_type: s.op_type.clone(),
                node: s.node.clone(),
                reason: "dense layer is not followed by Relu (only a leading diagonal normalisation Gemm may be)".into(),
            });
        }
        if k == last && s.relu {
            return Err(OnnxError::Node {
                op_type: s.op_type.clone(),
                node: s.node.clone(),
                reason: "the output layer is followed by Relu; friction outputs are linear".into(),
            });
        }
    }
    Ok(())
}

/// The normalisation `(x − mean)/scale` equal to the input affine map `a·x + c`.
fn normalisation_from_affine(a: &[f64], c: &[f64]) -> Result<Normalisation, OnnxError> {
    let n_in = a.len();
    let mut mean = Vec::with_capacity(n_in);
    let mut scale = Vec::with_capacity(n_in);
    for i in 0..n_in {
        if a[i] == 0.0 || !a[i].is_finite() {
            return Err(OnnxError::NotAChain(format!(
                "input {i} is multiplied by {} before the first layer; it cannot be a normalisation",
                a[i]
            )));
        }
        let s = 1.0 / a[i];
        scale.push(s as f32);
        mean.push((-c[i] * s) as f32);
    }
    Ok(Normalisation { mean, scale })
}

fn names<'a>(it: impl Iterator<Item = &'a str>) -> String {
    let v: Vec<String> = it.map(|s| format!("`{s}`")).collect();
    if v.is_empty() {
        "none".into()
    } else {
        v.join(", ")
    }
}

fn node_label(node: &NodeProto, index: usize) -> String {
    if node.name.is_empty() {
        format!("#{index}")
    } else {
        node.name.clone()
    }
}

fn node_err(node: &NodeProto, index: usize, reason: impl Into<String>) -> OnnxError {
    OnnxError::Node {
        op_type: node.op_type.clone(),
        node: node_label(node, index),
        reason: reason.into(),
    }
}

fn elem_type_name(t: i32) -> String {
    match <DataType as protobuf::Enum>::from_i32(t) {
        Some(d) => format!("{d:?}"),
        None => format!("code {t}"),
    }
}

/// Checks a graph input/output is float32 `[batch, n]`; returns (fixed batch dim, fixed width).
fn io_shape(
    v: &ValueInfoProto,
    what: &'static str,
) -> Result<(Option<i64>, Option<usize>), OnnxError> {
    let bad = |reason: String| OnnxError::BadShape {
        what,
        name: v.name.clone(),
        reason,
    };
    let Some(type_proto::Value::TensorType(t)) = v.type_.as_ref().and_then(|t| t.value.as_ref())
    else {
        return Err(bad("not a tensor".into()));
    };
    if t.elem_type != DataType::FLOAT as i32 {
        return Err(OnnxError::NonFloat {
            what,
            name: v.name.clone(),
            elem_type: elem_type_name(t.elem_type),
        });
    }
    let Some(shape) = t.shape.as_ref() else {
        return Ok((None, None));
    };
    if shape.dim.len() != 2 {
        return Err(bad(format!(
            "rank {} shape; expected [batch, features]",
            shape.dim.len()
        )));
    }
    let fixed = |d: &Dimension| match d.value {
        Some(dimension::Value::DimValue(v)) => Some(v),
        _ => None,
    };
    let width = match fixed(&shape.dim[1]) {
        Some(w) if w >= 1 => Some(w as usize),
        Some(w) => return Err(bad(format!("feature dimension {w} is not positive"))),
        None => None,
    };
    Ok((fixed(&shape.dim[0]), width))
}

/// Reads a float32 initializer as f64 values and its dims.
fn read_f32_tensor(t: &TensorProto) -> Result<(Vec<usize>, Vec<f64>), OnnxError> {
    let err = |reason: String| OnnxError::Tensor {
        name: t.name.clone(),
        reason,
    };
    if t.data_type != DataType::FLOAT as i32 {
        return Err(OnnxError::NonFloat {
            what: "tensor",
            name: t.name.clone(),
            elem_type: elem_type_name(t.data_type),
        });
    }
    if t.data_location.value() == DataLocation::EXTERNAL as i32 || !t.external_data.is_empty() {
        return Err(err(
            "external data is not supported (save the model as one file)".into(),
        ));
    }
    if t.segment.is_some() {
        return Err(err("segmented tensors are not supported".into()));
    }
    let mut dims = Vec::with_capacity(t.dims.len());
    let mut numel: usize = 1;
    for &d in &t.dims {
        let d = usize::try_from(d).map_err(|_| err(format!("negative dimension {d}")))?;
        numel = numel
            .checked_mul(d)
            .filter(|&n| n <= (1 << 28))
            .ok_or_else(|| err(format!("dimensions {:?} are too large", t.dims)))?;
        dims.push(d);
    }
    let values: Vec<f64> = if !t.raw_data.is_empty() {
        if t.raw_data.len() != 4 * numel {
            return Err(err(format!(
                "raw_data has {} bytes, dims {:?} need {}",
                t.raw_data.len(),
                t.dims,
                4 * numel
            )));
        }
        t.raw_data
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
            .collect()
    } else {
        if t.float_data.len() != numel {
            return Err(err(format!(
                "float_data has {} values, dims {:?} need {}",
                t.float_data.len(),
                t.dims,
                numel
            )));
        }
        t.float_data.iter().map(|&v| v as f64).collect()
    };
    if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(err(format!("value [{i}] = {v} is not finite")));
    }
    Ok((dims, values))
}

/// One dense layer found in the graph, in f64 (converted to f32 once at the end).
struct Stage {
    n_in: usize,
    n_out: usize,
    /// Row-major `[n_out][n_in]`.
    weight: Vec<f64>,
    bias: Vec<f64>,
    relu: bool,
    node: String,
    op_type: String,
}

/// State while walking the chain.
struct Chain {
    stages: Vec<Stage>,
    /// Element-wise `a_i·x_i + c_i` applied before the first layer.
    input_affine: Option<(Vec<f64>, Vec<f64>)>,
    /// Width of the current value, when known.
    width: Option<usize>,
}

impl Chain {
    fn new(width: Option<usize>) -> Self {
        Self {
            stages: Vec::new(),
            input_affine: None,
            width,
        }
    }
}

fn int_attr(node: &NodeProto, k: usize, name: &str, default: i64) -> Result<i64, OnnxError> {
    match node.attribute.iter().find(|a| a.name == name) {
        None => Ok(default),
        Some(a) if a.type_.value() == AttributeType::INT as i32 => Ok(a.i),
        Some(_) => Err(node_err(
            node,
            k,
            format!("attribute `{name}` is not an int"),
        )),
    }
}

fn float_attr(node: &NodeProto, k: usize, name: &str, default: f32) -> Result<f32, OnnxError> {
    match node.attribute.iter().find(|a| a.name == name) {
        None => Ok(default),
        Some(a) if a.type_.value() == AttributeType::FLOAT as i32 => Ok(a.f),
        Some(_) => Err(node_err(
            node,
            k,
            format!("attribute `{name}` is not a float"),
        )),
    }
}

/// Walks the graph from `input` to `output`, one node at a time.
fn walk(
    graph: &GraphProto,
    consts: &HashMap<&str, &TensorProto>,
    constant_nodes: &HashSet<usize>,
    input: &str,
    output: &str,
    chain: &mut Chain,
) -> Result<(), OnnxError> {
    let mut consumers: HashMap<&str, Vec<usize>> = HashMap::new();
    for (k, node) in graph.node.iter().enumerate() {
        if constant_nodes.contains(&k) {
            continue;
        }
        for i in &node.input {
            if !i.is_empty() {
                consumers.entry(i.as_str()).or_default().push(k);
            }
        }
    }
    let mut visited = vec![false; graph.node.len()];
    let mut current = input.to_string();
    loop {
        let users = consumers.get(current.as_str()).map_or(&[][..], |v| &v[..]);
        if current == output {
            if let Some(&k) = users.first() {
                let n = &graph.node[k];
                return Err(OnnxError::NotAChain(format!(
                    "graph output `{output}` also feeds node `{}` ({})",
                    node_label(n, k),
                    n.op_type
                )));
            }
            break;
        }
        let k = match users {
            [] => {
                return Err(OnnxError::NotAChain(format!(
                    "value `{current}` is not used by any node and is not the graph output `{output}`"
                )));
            }
            [k] => *k,
            many => {
                let list = names(many.iter().map(|&k| graph.node[k].name.as_str()));
                return Err(OnnxError::NotAChain(format!(
                    "value `{current}` feeds {} nodes ({list})",
                    many.len()
                )));
            }
        };
        if visited[k] {
            return Err(OnnxError::NotAChain(format!(
                "cycle through node `{}`",
                node_label(&graph.node[k], k)
            )));
        }
        visited[k] = true;
        let node = &graph.node[k];
        if !node.domain.is_empty() && node.domain != "ai.onnx" {
            return Err(OnnxError::UnsupportedOp {
                op_type: format!("{}::{}", node.domain, node.op_type),
                node: node_label(node, k),
            });
        }
        let out = node
            .output
            .first()
            .filter(|o| !o.is_empty())
            .ok_or_else(|| node_err(node, k, "has no output"))?;
        // Extra outputs (e.g. Dropout's mask) must be unused.
        for extra in node.output.iter().skip(1).filter(|o| !o.is_empty()) {
            if consumers.contains_key(extra.as_str()) || extra == output {
                return Err(node_err(
                    node,
                    k,
                    format!(
                        "second output `{extra}` is used; only single-output ops are supported"
                    ),
                ));
            }
        }
        step(node, k, &current, consts, chain)?;
        current = out.clone();
    }
    for (k, node) in graph.node.iter().enumerate() {
        if !visited[k] && !constant_nodes.contains(&k) {
            return Err(OnnxError::NotAChain(format!(
                "node `{}` ({}) is not on the input→output chain",
                node_label(node, k),
                node.op_type
            )));
        }
    }
    Ok(())
}

/// The constant operand of a binary op whose other operand is `current`; returns (const, current is first).
fn binary_operand<'a>(
    node: &NodeProto,
    k: usize,
    current: &str,
    consts: &HashMap<&str, &'a TensorProto>,
) -> Result<(&'a TensorProto, bool), OnnxError> {
    if node.input.len() != 2 {
        return Err(node_err(
            node,
            k,
            format!("has {} inputs, expected 2", node.input.len()),
        ));
    }
    let (other, first) = if node.input[0] == current {
        (&node.input[1], true)
    } else {
        (&node.input[0], false)
    };
    if other == current {
        return Err(node_err(
            node,
            k,
            "uses the running value twice (not an affine map)",
        ));
    }
    let t = consts.get(other.as_str()).ok_or_else(|| {
        node_err(
            node,
            k,
            format!("operand `{other}` is not an initializer or Constant"),
        )
    })?;
    Ok((t, first))
}

/// Broadcasts a constant of numel 1 or `n` (dims `[n]`, `[1, n]`, `[1]`, `[]`) to length `n`.
fn broadcast(
    node: &NodeProto,
    k: usize,
    name: &str,
    dims: &[usize],
    v: Vec<f64>,
    n: usize,
) -> Result<Vec<f64>, OnnxError> {
    let lead_ones = dims.len() <= 1 || dims[..dims.len() - 1].iter().all(|&d| d == 1);
    if !lead_ones || dims.len() > 2 {
        return Err(node_err(
            node,
            k,
            format!("constant `{name}` of shape {dims:?} does not broadcast per feature"),
        ));
    }
    match v.len() {
        1 => Ok(vec![v[0]; n]),
        m if m == n => Ok(v),
        m => Err(node_err(
            node,
            k,
            format!("constant `{name}` has {m} values, the running value has {n} features"),
        )),
    }
}

/// Applies one node of the chain to `chain`: a dense layer, a Relu, a no-op, or an element-wise
/// affine op folded into the previous layer (or the input affine map).
fn step(
    node: &NodeProto,
    k: usize,
    current: &str,
    consts: &HashMap<&str, &TensorProto>,
    chain: &mut Chain,
) -> Result<(), OnnxError> {
    match node.op_type.as_str() {
        "Gemm" | "MatMul" => step_dense(node, k, current, consts, chain)?,
        "Relu" => match chain.stages.last_mut() {
            Some(s) if !s.relu => s.relu = true,
            Some(_) => return Err(node_err(node, k, "Relu applied twice")),
            None => return Err(node_err(node, k, "Relu before the first dense layer")),
        },
        "Identity" => {}
        "Dropout" => {
            if node.input.iter().filter(|s| !s.is_empty()).count() != 1 {
                return Err(node_err(
                    node,
                    k,
                    "Dropout with ratio/training_mode inputs is not supported (export in eval mode)",
                ));
            }
        }
        "Add" | "Sub" | "Mul" | "Div" => {
            let (p, q) = elementwise_affine(node, k, current, consts, chain.width)?;
            fold_affine(node, k, chain, &p, &q)?;
        }
        _ => {
            return Err(OnnxError::UnsupportedOp {
                op_type: node.op_type.clone(),
                node: node_label(node, k),
            });
        }
    }
    Ok(())
}

/// A `Gemm` or `MatMul` with constant weights: appends a dense stage (weights scaled by `alpha`,
/// bias by `beta`).
fn step_dense(
    node: &NodeProto,
    k: usize,
    current: &str,
    consts: &HashMap<&str, &TensorProto>,
    chain: &mut Chain,
) -> Result<(), OnnxError> {
    let label = node_label(node, k);
    let is_gemm = node.op_type == "Gemm";
    let n_inputs = node.input.iter().filter(|s| !s.is_empty()).count();
    let ok_inputs = if is_gemm {
        (2..=3).contains(&n_inputs)
    } else {
        n_inputs == 2
    };
    if !ok_inputs || node.input[0] != current {
        return Err(node_err(
            node,
            k,
            "the running value must be the first input, with constant weights",
        ));
    }
    let (trans_a, trans_b, alpha, beta) = if is_gemm {
        (
            int_attr(node, k, "transA", 0)?,
            int_attr(node, k, "transB", 0)?,
            float_attr(node, k, "alpha", 1.0)? as f64,
            float_attr(node, k, "beta", 1.0)? as f64,
        )
    } else {
        (0, 0, 1.0, 1.0)
    };
    if trans_a != 0 {
        return Err(node_err(node, k, "transA = 1 is not supported"));
    }
    let b_name = &node.input[1];
    let bt = consts.get(b_name.as_str()).ok_or_else(|| {
        node_err(
            node,
            k,
            format!("weight `{b_name}` is not an initializer or Constant"),
        )
    })?;
    let (dims, b) = read_f32_tensor(bt)?;
    if dims.len() != 2 {
        return Err(node_err(
            node,
            k,
            format!("weight `{b_name}` has shape {dims:?}, expected 2-D"),
        ));
    }
    // transB = 0: B is [K, N]; transB = 1: B is [N, K].
    let (n_in, n_out) = if trans_b != 0 {
        (dims[1], dims[0])
    } else {
        (dims[0], dims[1])
    };
    if let Some(w) = chain.width
        && w != n_in
    {
        return Err(node_err(
            node,
            k,
            format!(
                "weight `{b_name}` {dims:?} (transB={trans_b}) takes {n_in} inputs, the running value has {w}"
            ),
        ));
    }
    let mut weight = vec![0.0; n_in * n_out];
    for o in 0..n_out {
        for i in 0..n_in {
            let v = if trans_b != 0 {
                b[o * n_in + i]
            } else {
                b[i * n_out + o]
            };
            weight[o * n_in + i] = alpha * v;
        }
    }
    let bias = dense_bias(node, k, consts, n_out, beta)?;
    chain.stages.push(Stage {
        n_in,
        n_out,
        weight,
        bias,
        relu: false,
        node: label,
        op_type: node.op_type.clone(),
    });
    chain.width = Some(n_out);
    Ok(())
}

/// The bias of a dense node (its optional third input, broadcast to `n_out` and scaled by `beta`),
/// zeros if absent.
fn dense_bias(
    node: &NodeProto,
    k: usize,
    consts: &HashMap<&str, &TensorProto>,
    n_out: usize,
    beta: f64,
) -> Result<Vec<f64>, OnnxError> {
    Ok(match node.input.get(2).filter(|s| !s.is_empty()) {
        Some(c_name) => {
            let ct = consts.get(c_name.as_str()).ok_or_else(|| {
                node_err(
                    node,
                    k,
                    format!("bias `{c_name}` is not an initializer or Constant"),
                )
            })?;
            let (cd, c) = read_f32_tensor(ct)?;
            let c = broadcast(node, k, c_name, &cd, c, n_out)?;
            c.into_iter().map(|v| beta * v).collect()
        }
        None => vec![0.0; n_out],
    })
}

/// An `Add`/`Sub`/`Mul`/`Div` with a constant operand as the per-feature affine map
/// `y = p·x + q`, `x` the running value of width `width`.
fn elementwise_affine(
    node: &NodeProto,
    k: usize,
    current: &str,
    consts: &HashMap<&str, &TensorProto>,
    width: Option<usize>,
) -> Result<(Vec<f64>, Vec<f64>), OnnxError> {
    let (t, first) = binary_operand(node, k, current, consts)?;
    let (dims, v) = read_f32_tensor(t)?;
    let n = width.ok_or_else(|| {
        node_err(
            node,
            k,
            "the feature width is unknown here (give the graph input a fixed width)",
        )
    })?;
    let v = broadcast(node, k, &t.name, &dims, v, n)?;
    // y = p·x + q per feature, x the running value.
    Ok(match (node.op_type.as_str(), first) {
        ("Add", _) => (vec![1.0; n], v),
        ("Sub", true) => (vec![1.0; n], v.iter().map(|x| -x).collect()),
        ("Sub", false) => (vec![-1.0; n], v),
        ("Mul", _) => (v, vec![0.0; n]),
        ("Div", true) => {
            if let Some(i) = v.iter().position(|&d| d == 0.0) {
                return Err(node_err(node, k, format!("divides feature {i} by zero")));
            }
            (v.iter().map(|d| 1.0 / d).collect(), vec![0.0; n])
        }
        _ => {
            return Err(node_err(
                node,
                k,
                "divides a constant by the running value (not affine)",
            ));
        }
    })
}

/// Folds `y = p·x + q` into the last dense stage (before its Relu), or into the input affine map
/// when no stage exists yet.
fn fold_affine(
    node: &NodeProto,
    k: usize,
    chain: &mut Chain,
    p: &[f64],
    q: &[f64],
) -> Result<(), OnnxError> {
    let n = p.len();
    match chain.stages.last_mut() {
        None => {
            let (a, c) = chain
                .input_affine
                .get_or_insert_with(|| (vec![1.0; n], vec![0.0; n]));
            for i in 0..n {
                a[i] *= p[i];
                c[i] = p[i] * c[i] + q[i];
            }
        }
        Some(s) if !s.relu => {
            for o in 0..s.n_out {
                for w in &mut s.weight[o * s.n_in..(o + 1) * s.n_in] {
                    *w *= p[o];
                }
                s.bias[o] = p[o] * s.bias[o] + q[o];
            }
        }
        Some(_) => {
            return Err(node_err(
                node,
                k,
                "element-wise op after Relu cannot be folded into a dense layer",
            ));
        }
    }
    Ok(())
}

/// The diagonal of a square stage, after checking the off-diagonal entries.
fn diagonal_of(s: &Stage) -> Result<Vec<f64>, OnnxError> {
    let n = s.n_in;
    let not_diag = |row, col, value| OnnxError::NotDiagonal {
        node: s.node.clone(),
        n,
        row,
        col,
        value,
    };
    if s.n_out != n {
        return Err(OnnxError::Node {
            op_type: s.op_type.clone(),
            node: s.node.clone(),
            reason: format!(
                "{}x{} dense layer is not followed by Relu (only a leading diagonal normalisation Gemm may be)",
                s.n_out, s.n_in
            ),
        });
    }
    let diag: Vec<f64> = (0..n).map(|i| s.weight[i * n + i]).collect();
    let max_diag = diag.iter().fold(0.0f64, |m, d| m.max(d.abs()));
    for (i, &d) in diag.iter().enumerate() {
        if d == 0.0 {
            return Err(not_diag(i, i, 0.0));
        }
        for (j, &v) in s.weight[i * n..(i + 1) * n].iter().enumerate() {
            if i != j && v != 0.0 && v.abs() >= DIAGONAL_REL_TOL * max_diag {
                return Err(not_diag(i, j, v));
            }
        }
    }
    Ok(diag)
}

// ---------------------------------------------------------------------------------------------
// Export
// ---------------------------------------------------------------------------------------------

fn f32_tensor(name: &str, dims: &[usize], values: impl IntoIterator<Item = f32>) -> TensorProto {
    let mut t = TensorProto::new();
    t.name = name.to_string();
    t.data_type = DataType::FLOAT as i32;
    t.dims = dims.iter().map(|&d| d as i64).collect();
    t.raw_data = values.into_iter().flat_map(f32::to_le_bytes).collect();
    t
}

fn int_attribute(name: &str, v: i64) -> AttributeProto {
    let mut a = AttributeProto::new();
    a.name = name.to_string();
    a.type_ = AttributeType::INT.into();
    a.i = v;
    a
}

fn make_node(
    op: &str,
    name: &str,
    inputs: &[&str],
    output: &str,
    attrs: Vec<AttributeProto>,
) -> NodeProto {
    let mut n = NodeProto::new();
    n.op_type = op.to_string();
    n.name = name.to_string();
    n.input = inputs.iter().map(|s| s.to_string()).collect();
    n.output = vec![output.to_string()];
    n.attribute = attrs;
    n
}

/// A float32 `[batch, width]` value description with a dynamic batch dimension.
pub fn batch_value_info(name: &str, width: usize) -> ValueInfoProto {
    let mut batch = Dimension::new();
    batch.value = Some(dimension::Value::DimParam("batch".into()));
    let mut w = Dimension::new();
    w.value = Some(dimension::Value::DimValue(width as i64));
    let mut shape = TensorShapeProto::new();
    shape.dim = vec![batch, w];
    let mut tt = type_proto::Tensor::new();
    tt.elem_type = DataType::FLOAT as i32;
    tt.shape = protobuf::MessageField::some(shape);
    let mut tp = TypeProto::new();
    tp.value = Some(type_proto::Value::TensorType(tt));
    let mut v = ValueInfoProto::new();
    v.name = name.to_string();
    v.type_ = protobuf::MessageField::some(tp);
    v
}

/// Builds the ONNX model for `mlp` (validated first). See the module doc for the graph layout.
pub fn export_model(mlp: &MlpWeights, opts: &ExportOptions) -> Result<ModelProto, OnnxError> {
    mlp.validate()?;
    let n = mlp.n_inputs();
    let mut graph = GraphProto::new();
    graph.name = "frictionless_mlp".into();
    graph.input.push(batch_value_info("input", n));
    graph
        .output
        .push(batch_value_info("output", mlp.n_outputs()));
    let mut current = "input".to_string();
    if push_normalisation(&mut graph, mlp, opts.norm) {
        current = "norm_out".into();
    }
    push_layers(&mut graph, mlp, current);
    let mut model = ModelProto::new();
    model.ir_version = 7;
    let mut op = OperatorSetIdProto::new();
    op.version = EXPORT_OPSET;
    model.opset_import.push(op);
    model.producer_name = "frictl".into();
    model.producer_version = env!("CARGO_PKG_VERSION").into();
    model.doc_string =
        "frictionless friction MLP: raw input [batch, n] -> joint-side friction torque [Nm]".into();
    model.metadata_props = opts
        .metadata
        .iter()
        .map(|(k, v)| {
            let mut e = StringStringEntryProto::new();
            e.key = k.clone();
            e.value = v.clone();
            e
        })
        .collect();
    model.graph = protobuf::MessageField::some(graph);
    Ok(model)
}

/// Adds the input normalisation as `norm_out` (`norm`: as Sub and Div, or as one diagonal Gemm);
/// false, adding nothing, when it is the identity.
fn push_normalisation(graph: &mut GraphProto, mlp: &MlpWeights, norm: NormExport) -> bool {
    let n = mlp.n_inputs();
    let identity =
        mlp.norm.mean.iter().all(|&m| m == 0.0) && mlp.norm.scale.iter().all(|&s| s == 1.0);
    if identity {
        return false;
    }
    match norm {
        NormExport::SubDiv => {
            graph
                .initializer
                .push(f32_tensor("norm.mean", &[n], mlp.norm.mean.iter().copied()));
            graph.initializer.push(f32_tensor(
                "norm.scale",
                &[n],
                mlp.norm.scale.iter().copied(),
            ));
            graph.node.push(make_node(
                "Sub",
                "norm_sub",
                &["input", "norm.mean"],
                "norm_centered",
                vec![],
            ));
            graph.node.push(make_node(
                "Div",
                "norm_div",
                &["norm_centered", "norm.scale"],
                "norm_out",
                vec![],
            ));
        }
        NormExport::DiagonalGemm => {
            let mut w = vec![0f32; n * n];
            let mut b = vec![0f32; n];
            for i in 0..n {
                let inv = 1.0 / mlp.norm.scale[i] as f64;
                w[i * n + i] = inv as f32;
                b[i] = (-(mlp.norm.mean[i] as f64) * inv) as f32;
            }
            graph
                .initializer
                .push(f32_tensor("norm.weight", &[n, n], w));
            graph.initializer.push(f32_tensor("norm.bias", &[n], b));
            graph.node.push(make_node(
                "Gemm",
                "norm_gemm",
                &["input", "norm.weight", "norm.bias"],
                "norm_out",
                vec![int_attribute("transB", 1)],
            ));
        }
    }
    true
}

/// Adds every layer after `current` as a Gemm with its weight and bias, a Relu after each but
/// the last, whose output is `output`.
fn push_layers(graph: &mut GraphProto, mlp: &MlpWeights, mut current: String) {
    let last = mlp.layers.len() - 1;
    for (k, l) in mlp.layers.iter().enumerate() {
        let w = format!("layers.{k}.weight");
        let b = format!("layers.{k}.bias");
        graph
            .initializer
            .push(f32_tensor(&w, &[l.n_out, l.n_in], l.weight.iter().copied()));
        graph
            .initializer
            .push(f32_tensor(&b, &[l.n_out], l.bias.iter().copied()));
        let out = if k == last {
            "output".to_string()
        } else {
            format!("gemm_{k}")
        };
        graph.node.push(make_node(
            "Gemm",
            &format!("gemm_{k}"),
            &[&current, &w, &b],
            &out,
            vec![int_attribute("transB", 1)],
        ));
        current = out;
        if k != last {
            let r = format!("relu_{k}");
            graph
                .node
                .push(make_node("Relu", &r, &[&current], &r, vec![]));
            current = r;
        }
    }
}

/// Serialises `mlp` as ONNX bytes.
pub fn export_bytes(mlp: &MlpWeights, opts: &ExportOptions) -> Result<Vec<u8>, OnnxError> {
    export_model(mlp, opts)?
        .write_to_bytes()
        .map_err(|e| OnnxError::Encode(e.to_string()))
}

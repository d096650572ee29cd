//! The ergoCub anchor fixture, a tiny ONNX graph builder (onnx-protobuf messages, independent of
//! the exporter under test) and tolerance checks, for the interop and frictl tests.

use std::path::PathBuf;

use onnx_protobuf::attribute_proto::AttributeType;
use onnx_protobuf::tensor_proto::DataType;
use onnx_protobuf::tensor_shape_proto::{Dimension, dimension};
use onnx_protobuf::{
    AttributeProto, GraphProto, Message, ModelProto, NodeProto, OperatorSetIdProto, TensorProto,
    TensorShapeProto, TypeProto, ValueInfoProto, type_proto,
};
use rand::{Rng, SeedableRng};

/// Path of the anchor ONNX model (without extension).
pub fn anchor_base() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures/ergocub/blf_jtc_ergoCubSN002_l_ankle_roll_pinn_2024-06")
}

/// The anchor ONNX path.
pub fn anchor_onnx() -> PathBuf {
    anchor_base().with_extension("onnx")
}

/// The anchor reference I/O JSON.
pub fn anchor_json() -> serde_json::Value {
    let p = anchor_base().with_extension("reference_io.json");
    serde_json::from_slice(&std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .expect("anchor JSON parses")
}

/// JSON array of numbers → Vec<f32>.
pub fn f32s(v: &serde_json::Value) -> Vec<f32> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number") as f32)
        .collect()
}

/// numpy `allclose`: |got − want| ≤ atol + rtol·|want|. f32 outputs near zero are dominated by
/// cancellation, where a pure relative bound is meaningless; atol is the floor for those.
pub fn assert_close(got: f32, want: f32, rtol: f64, atol: f64, what: &str) {
    let (g, w) = (got as f64, want as f64);
    assert!(
        (g - w).abs() <= atol + rtol * w.abs(),
        "{what}: got {got}, want {want} (|diff| {:.3e}, allowed {:.3e})",
        (g - w).abs(),
        atol + rtol * w.abs()
    );
}

/// A float32 initializer, stored as raw_data or float_data.
pub fn tensor(name: &str, dims: &[usize], v: &[f32], float_data: bool) -> TensorProto {
    let mut t = TensorProto::new();
    t.name = name.into();
    t.data_type = DataType::FLOAT as i32;
    t.dims = dims.iter().map(|&d| d as i64).collect();
    if float_data {
        t.float_data = v.to_vec();
    } else {
        t.raw_data = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    }
    t
}

/// An int attribute.
pub fn attr_i(name: &str, v: i64) -> AttributeProto {
    let mut a = AttributeProto::new();
    a.name = name.into();
    a.type_ = AttributeType::INT.into();
    a.i = v;
    a
}

/// A float attribute.
pub fn attr_f(name: &str, v: f32) -> AttributeProto {
    let mut a = AttributeProto::new();
    a.name = name.into();
    a.type_ = AttributeType::FLOAT.into();
    a.f = v;
    a
}

/// A node.
pub fn node(
    op: &str,
    name: &str,
    inputs: &[&str],
    outputs: &[&str],
    attrs: Vec<AttributeProto>,
) -> NodeProto {
    let mut n = NodeProto::new();
    n.op_type = op.into();
    n.name = name.into();
    n.input = inputs.iter().map(|s| s.to_string()).collect();
    n.output = outputs.iter().map(|s| s.to_string()).collect();
    n.attribute = attrs;
    n
}

/// A `[batch, width]` value info of the given element type.
pub fn value_info(name: &str, width: usize, elem: DataType) -> ValueInfoProto {
    let mut b = Dimension::new();
    b.value = Some(dimension::Value::DimParam("batch".into()));
    let mut w = Dimension::new();
    w.value = Some(dimension::Value::DimValue(width as i64));
    let mut shape = TensorShapeProto::new();
    shape.dim = vec![b, w];
    let mut tt = type_proto::Tensor::new();
    tt.elem_type = elem as i32;
    tt.shape = protobuf::MessageField::some(shape);
    let mut tp = TypeProto::new();
    tp.value = Some(type_proto::Value::TensorType(tt));
    let mut v = ValueInfoProto::new();
    v.name = name.into();
    v.type_ = protobuf::MessageField::some(tp);
    v
}

/// A model from parts (float input `input` of `n_in`, float outputs of width 1).
pub fn model(
    nodes: Vec<NodeProto>,
    inits: Vec<TensorProto>,
    n_in: usize,
    outputs: &[&str],
    opset: i64,
) -> ModelProto {
    let mut g = GraphProto::new();
    g.name = "test".into();
    g.node = nodes;
    g.initializer = inits;
    g.input.push(value_info("input", n_in, DataType::FLOAT));
    for o in outputs {
        g.output.push(value_info(o, 1, DataType::FLOAT));
    }
    let mut m = ModelProto::new();
    m.ir_version = 7;
    let mut op = OperatorSetIdProto::new();
    op.version = opset;
    m.opset_import.push(op);
    m.graph = protobuf::MessageField::some(g);
    m
}

/// Serialised bytes.
pub fn bytes(m: &ModelProto) -> Vec<u8> {
    m.write_to_bytes().expect("encode")
}

/// A random matrix (row-major rows×cols) and vector, reproducible from `seed`.
pub fn random(seed: u64, len: usize, amp: f32) -> Vec<f32> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    (0..len).map(|_| rng.random_range(-amp..amp)).collect()
}

/// Direct f64 evaluation of `relu(x·B + c)` chains as ONNX defines them, with B in `[in, out]`
/// layout — independent of the importer's transposition logic.
pub fn eval_in_out(x: &[f32], layers: &[(Vec<f32>, Vec<f32>, usize, usize)]) -> f64 {
    let mut a: Vec<f64> = x.iter().map(|&v| v as f64).collect();
    for (k, (b_in_out, c, n_in, n_out)) in layers.iter().enumerate() {
        let mut y = vec![0f64; *n_out];
        for (o, yo) in y.iter_mut().enumerate() {
            let mut acc = c[o] as f64;
            for i in 0..*n_in {
                acc += a[i] * b_in_out[i * n_out + o] as f64;
            }
            *yo = if k + 1 < layers.len() {
                acc.max(0.0)
            } else {
                acc
            };
        }
        a = y;
    }
    a[0]
}

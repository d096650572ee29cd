//! safetensors import/export: PyTorch `nn.Sequential` state dicts in both index spacings, prefixes,
//! reduced-precision tensors, normalisation sources and error cases.

use frictionless_test_support::onnx as interop_common;

use std::collections::HashMap;

use ::safetensors::tensor::{Dtype, SafeTensors, TensorView};
use frictionless::mlp::{Activation, DenseLayer, MlpWeights, Normalisation};
use frictionless_interop::safetensors::{self, NormSource, SafetensorsError};
use interop_common::random;

fn mlp(sizes: &[usize]) -> MlpWeights {
    let layers = sizes
        .windows(2)
        .enumerate()
        .map(|(k, w)| DenseLayer {
            n_in: w[0],
            n_out: w[1],
            weight: random(k as u64, w[0] * w[1], 0.5),
            bias: random(50 + k as u64, w[1], 0.2),
            activation: if k + 2 == sizes.len() {
                Activation::Identity
            } else {
                Activation::Relu
            },
        })
        .collect();
    MlpWeights {
        norm: Normalisation {
            mean: random(99, sizes[0], 2.0),
            scale: random(98, sizes[0], 1.0)
                .iter()
                .map(|v| v.abs() + 0.1)
                .collect(),
        },
        layers,
    }
}

/// A state dict written the way PyTorch would: (name, dtype, shape, bytes).
type Entry = (String, Dtype, Vec<usize>, Vec<u8>);

fn le32(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn state_dict(m: &MlpWeights, spacing: usize, prefix: &str) -> Vec<Entry> {
    let mut v = Vec::new();
    for (k, l) in m.layers.iter().enumerate() {
        v.push((
            format!("{prefix}{}.weight", k * spacing),
            Dtype::F32,
            vec![l.n_out, l.n_in],
            le32(&l.weight),
        ));
        v.push((
            format!("{prefix}{}.bias", k * spacing),
            Dtype::F32,
            vec![l.n_out],
            le32(&l.bias),
        ));
    }
    v
}

fn serialize(entries: &[Entry], meta: Option<HashMap<String, String>>) -> Vec<u8> {
    let views: Vec<(String, TensorView<'_>)> = entries
        .iter()
        .map(|(n, d, s, b)| (n.clone(), TensorView::new(*d, s.clone(), b).unwrap()))
        .collect();
    ::safetensors::tensor::serialize(views, meta).unwrap()
}

#[test]
fn export_import_round_trip_is_exact() {
    let m = mlp(&[10, 16, 8, 1]);
    let meta = vec![("frictionless.joint_name".to_string(), "r_knee".to_string())];
    let b = safetensors::export_bytes(&m, &meta).unwrap();
    let imp = safetensors::import_bytes(&b).unwrap();
    assert_eq!(imp.mlp, m);
    assert_eq!(imp.spacing, 2);
    assert_eq!(imp.norm_source, NormSource::Tensors);
    assert_eq!(
        imp.metadata
            .get("frictionless.joint_name")
            .map(String::as_str),
        Some("r_knee")
    );
    assert_eq!(imp.metadata.get("format").map(String::as_str), Some("pt"));
    // What we write, by name and PyTorch shape.
    let st = SafeTensors::deserialize(&b).unwrap();
    let mut names: Vec<String> = st.names().iter().map(|s| s.to_string()).collect();
    names.sort();
    assert_eq!(
        names,
        [
            "0.bias",
            "0.weight",
            "2.bias",
            "2.weight",
            "4.bias",
            "4.weight",
            "norm.mean",
            "norm.scale"
        ]
    );
    assert_eq!(st.tensor("2.weight").unwrap().shape(), [8, 16]);
}

#[test]
fn dropout_spacing_and_prefix_are_accepted() {
    let m = mlp(&[6, 12, 7, 1]);
    let mut e = state_dict(&m, 3, "net.");
    e.push((
        "net.norm.mean".into(),
        Dtype::F32,
        vec![6],
        le32(&m.norm.mean),
    ));
    e.push((
        "net.norm.scale".into(),
        Dtype::F32,
        vec![6],
        le32(&m.norm.scale),
    ));
    e.push((
        "phys".into(),
        Dtype::F32,
        vec![4],
        le32(&[1.0, 2.0, 3.0, 4.0]),
    ));
    let imp = safetensors::import_bytes(&serialize(&e, None)).unwrap();
    assert_eq!(imp.mlp, m);
    assert_eq!(imp.spacing, 3);
    assert_eq!(imp.prefix, "net.");
    assert_eq!(imp.ignored, ["phys"]);
}

#[test]
fn normalisation_from_metadata_or_identity() {
    let m = mlp(&[4, 5, 1]);
    let mut meta = HashMap::new();
    meta.insert(
        "norm.mean".to_string(),
        serde_json::to_string(&m.norm.mean).unwrap(),
    );
    meta.insert(
        "norm.scale".to_string(),
        serde_json::to_string(&m.norm.scale).unwrap(),
    );
    let imp = safetensors::import_bytes(&serialize(&state_dict(&m, 2, ""), Some(meta))).unwrap();
    assert_eq!(imp.norm_source, NormSource::Metadata);
    assert_eq!(imp.mlp.norm, m.norm);

    let imp = safetensors::import_bytes(&serialize(&state_dict(&m, 2, ""), None)).unwrap();
    assert_eq!(imp.norm_source, NormSource::Identity);
    assert_eq!(imp.mlp.norm, Normalisation::identity(4));
    assert_eq!(imp.mlp.layers, m.layers);

    let mut meta = HashMap::new();
    meta.insert("norm.mean".to_string(), "[1, 2, oops]".to_string());
    let err =
        safetensors::import_bytes(&serialize(&state_dict(&m, 2, ""), Some(meta))).unwrap_err();
    assert!(
        matches!(&err, SafetensorsError::Metadata { key, .. } if key == "norm.mean"),
        "{err}"
    );
}

#[test]
fn half_precision_tensors_are_widened() {
    let m = mlp(&[3, 4, 1]);
    let mut e = state_dict(&m, 2, "");
    let to_f16 = |v: &[f32]| -> Vec<u8> {
        v.iter()
            .flat_map(|x| half::f16::from_f32(*x).to_le_bytes())
            .collect()
    };
    let to_bf16 = |v: &[f32]| -> Vec<u8> {
        v.iter()
            .flat_map(|x| half::bf16::from_f32(*x).to_le_bytes())
            .collect()
    };
    e[0] = (
        e[0].0.clone(),
        Dtype::F16,
        e[0].2.clone(),
        to_f16(&m.layers[0].weight),
    );
    e[2] = (
        e[2].0.clone(),
        Dtype::BF16,
        e[2].2.clone(),
        to_bf16(&m.layers[1].weight),
    );
    let imp = safetensors::import_bytes(&serialize(&e, None)).unwrap();
    for (got, want) in imp.mlp.layers[0].weight.iter().zip(&m.layers[0].weight) {
        assert_eq!(*got, half::f16::from_f32(*want).to_f32());
    }
    for (got, want) in imp.mlp.layers[1].weight.iter().zip(&m.layers[1].weight) {
        assert_eq!(*got, half::bf16::from_f32(*want).to_f32());
    }
}

#[test]
fn transposed_weight_is_refused_with_its_name() {
    let m = mlp(&[3, 4, 2, 1]);
    let mut e = state_dict(&m, 2, "");
    e[2].2 = vec![4, 2]; // 2.weight stored [in, out]
    let err = safetensors::import_bytes(&serialize(&e, None)).unwrap_err();
    assert!(
        matches!(&err, SafetensorsError::Tensor { name, .. } if name == "2.weight"),
        "{err}"
    );
    assert!(err.to_string().contains("transposed"), "{err}");
}

#[test]
fn uneven_or_unknown_layouts_are_refused() {
    let m = mlp(&[3, 4, 2, 1]);
    let mut e = state_dict(&m, 2, "");
    e[4].0 = "5.weight".into();
    e[5].0 = "5.bias".into();
    let err = safetensors::import_bytes(&serialize(&e, None)).unwrap_err();
    assert!(
        matches!(&err, SafetensorsError::Spacing(v) if v == &[0, 2, 5]),
        "{err}"
    );

    let e = vec![(
        "encoder.weight".to_string(),
        Dtype::F32,
        vec![2, 2],
        le32(&[1.0; 4]),
    )];
    let err = safetensors::import_bytes(&serialize(&e, None)).unwrap_err();
    assert!(matches!(err, SafetensorsError::NoLayers(_)), "{err}");

    let mut e = state_dict(&m, 2, "");
    e[0].1 = Dtype::I32;
    let err = safetensors::import_bytes(&serialize(&e, None)).unwrap_err();
    assert!(err.to_string().contains("0.weight"), "{err}");

    let err = safetensors::import_bytes(b"definitely not safetensors").unwrap_err();
    assert!(matches!(err, SafetensorsError::Decode(_)), "{err}");
}

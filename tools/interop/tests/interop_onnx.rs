//! ONNX import/export: the real ergoCub model against its ONNX Runtime reference I/O, synthetic
//! graphs in every supported form, error cases, and export → import round trips.

use frictionless_test_support::onnx as interop_common;

use frictionless::kernel::{KernelPath, Mlp};
use frictionless::mlp::{Activation, MlpWeights, Normalisation, StorageDtype};
use frictionless::random::{RandomMlpSpec, seeded_mlp};
use frictionless_interop::onnx::{self, ExportOptions, NormExport, OnnxError};
use interop_common::*;
use onnx_protobuf::Message;
use sha2::Digest;

const RTOL: f64 = 1e-5;
/// Absolute floor [Nm] for outputs near zero (see `assert_close`): on the anchor's `training_mean`
/// case (output 0.0041 Nm) ORT itself is 2.5e-8 Nm (6e-6 relative) away from the exact f64 value.
const ATOL: f64 = 1e-6;

#[test]
fn anchor_file_is_the_published_blob() {
    let json = anchor_json();
    let bytes = std::fs::read(anchor_onnx()).unwrap();
    let sha: String = sha2::Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(sha, json["sha256"].as_str().unwrap());
}

#[test]
fn ergocub_model_imports_with_expected_shape() {
    let imp = onnx::import_file(&anchor_onnx()).unwrap();
    assert_eq!(imp.mlp.sizes(), vec![50, 450, 210, 280, 1]);
    assert_eq!(imp.opset, 12);
    assert_eq!(imp.ir_version, 7);
    assert_eq!(imp.input_name, "input");
    assert_eq!(imp.output_name, "output");
    assert_eq!(imp.batch_dim, None, "dynamic batch");
    assert!(imp.normalisation_found);
    assert!(imp.producer.starts_with("pytorch"), "{}", imp.producer);
    let acts: Vec<Activation> = imp.mlp.layers.iter().map(|l| l.activation).collect();
    assert_eq!(
        acts,
        [
            Activation::Relu,
            Activation::Relu,
            Activation::Relu,
            Activation::Identity
        ]
    );
}

#[test]
fn ergocub_model_reproduces_all_reference_cases() {
    let imp = onnx::import_file(&anchor_onnx()).unwrap();
    let json = anchor_json();
    let cases = json["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 9);
    let mut worst_rel = 0f64;
    for path in KernelPath::available() {
        let mut k = Mlp::new(&imp.mlp, StorageDtype::F32)
            .unwrap()
            .with_path(path)
            .unwrap();
        for c in cases {
            let name = c["name"].as_str().unwrap();
            let x = f32s(&c["input"]);
            let want = c["output"].as_f64().unwrap() as f32;
            let y_kernel = k.forward(&x);
            assert_close(
                y_kernel,
                want,
                RTOL,
                ATOL,
                &format!("kernel {path} case {name}"),
            );
            let y_ref = imp.mlp.forward_reference(&x)[0];
            assert_close(
                y_ref,
                want,
                RTOL,
                ATOL,
                &format!("forward_reference case {name}"),
            );
            if want.abs() > 0.1 {
                worst_rel = worst_rel.max(((y_kernel - want) / want).abs() as f64);
            }
        }
    }
    // Outputs away from zero meet the pure relative bound too.
    assert!(worst_rel <= RTOL, "worst relative error {worst_rel:e}");
}

#[test]
fn ergocub_normalisation_matches_the_folded_statistics() {
    let imp = onnx::import_file(&anchor_onnx()).unwrap();
    let json = anchor_json();
    let norm = &json["normalisation_folded_in_first_Gemm"];
    let (mean, scale) = (f32s(&norm["mean"]), f32s(&norm["scale_iqr"]));
    assert_eq!(mean.len(), 50);
    for i in 0..50 {
        // The Gemm stores 1/IQR and −mean/IQR in f32; inverting them costs a few ulps.
        assert_close(
            imp.mlp.norm.scale[i],
            scale[i],
            1e-6,
            0.0,
            &format!("scale[{i}]"),
        );
        assert_close(
            imp.mlp.norm.mean[i],
            mean[i],
            1e-5,
            1e-6 * scale[i] as f64,
            &format!("mean[{i}]"),
        );
    }
}

/// Builds a random MLP graph in the given form and checks the importer against a direct
/// evaluation of the ONNX semantics.
fn check_synthetic(
    form: &str,
    trans_b: i64,
    alpha: f32,
    beta: f32,
    float_data: bool,
    diag_norm: bool,
) {
    let sizes = [12usize, 20, 9, 1];
    let mut nodes = Vec::new();
    let mut inits = Vec::new();
    let mut direct: Vec<(Vec<f32>, Vec<f32>, usize, usize)> = Vec::new();
    let mut cur = "input".to_string();
    let n = sizes[0];
    let d = random(90, n, 2.0)
        .iter()
        .map(|v| v + 2.5)
        .collect::<Vec<f32>>();
    let e = random(91, n, 1.0);
    if diag_norm {
        let mut w = vec![0f32; n * n];
        for i in 0..n {
            w[i * n + i] = d[i];
        }
        inits.push(tensor("nw", &[n, n], &w, float_data));
        inits.push(tensor("nb", &[n], &e, float_data));
        nodes.push(node(
            "Gemm",
            "/norm/Gemm",
            &["input", "nw", "nb"],
            &["n0"],
            vec![attr_i("transB", 1)],
        ));
        direct.push((w.clone(), e.clone(), n, n)); // symmetric, so [in,out] == [out,in]
        cur = "n0".into();
    }
    for k in 0..sizes.len() - 1 {
        let (i, o) = (sizes[k], sizes[k + 1]);
        let b_in_out = random(100 + k as u64, i * o, 0.6);
        let c = random(200 + k as u64, o, 0.3);
        let (wn, bn) = (format!("w{k}"), format!("b{k}"));
        let out = if k + 2 == sizes.len() {
            "output".to_string()
        } else {
            format!("h{k}")
        };
        let scaled_c: Vec<f32>;
        match form {
            "gemm" => {
                let stored: Vec<f32> = if trans_b == 1 {
                    (0..o)
                        .flat_map(|oo| (0..i).map(move |ii| (oo, ii)))
                        .map(|(oo, ii)| b_in_out[ii * o + oo])
                        .collect()
                } else {
                    b_in_out.clone()
                };
                let dims = if trans_b == 1 { [o, i] } else { [i, o] };
                inits.push(tensor(&wn, &dims, &stored, float_data));
                inits.push(tensor(&bn, &[1, o], &c, float_data));
                nodes.push(node(
                    "Gemm",
                    &format!("/l{k}/Gemm"),
                    &[&cur, &wn, &bn],
                    &[&out],
                    vec![
                        attr_i("transB", trans_b),
                        attr_f("alpha", alpha),
                        attr_f("beta", beta),
                    ],
                ));
                let w_scaled = b_in_out.iter().map(|v| v * alpha).collect();
                scaled_c = c.iter().map(|v| v * beta).collect();
                direct.push((w_scaled, scaled_c, i, o));
            }
            _ => {
                inits.push(tensor(&wn, &[i, o], &b_in_out, float_data));
                inits.push(tensor(&bn, &[o], &c, float_data));
                let mm = format!("mm{k}");
                nodes.push(node(
                    "MatMul",
                    &format!("/l{k}/MatMul"),
                    &[&cur, &wn],
                    &[&mm],
                    vec![],
                ));
                nodes.push(node(
                    "Add",
                    &format!("/l{k}/Add"),
                    &[&bn, &mm],
                    &[&out],
                    vec![],
                ));
                direct.push((b_in_out, c, i, o));
            }
        }
        cur = out;
        if k + 2 < sizes.len() {
            let r = format!("r{k}");
            nodes.push(node("Relu", &format!("/relu{k}"), &[&cur], &[&r], vec![]));
            cur = r;
        }
    }
    let m = model(nodes, inits, n, &["output"], 13);
    let imp = onnx::import_bytes(&bytes(&m)).unwrap();
    assert_eq!(imp.mlp.sizes(), sizes.to_vec(), "{form}");
    assert_eq!(imp.normalisation_found, diag_norm);
    // The direct evaluation applies the normaliser as a plain linear layer (no ReLU).
    let eval = |x: &[f32]| -> f64 {
        if diag_norm {
            let xn: Vec<f32> = (0..n).map(|i| x[i] * d[i] + e[i]).collect();
            eval_in_out(&xn, &direct[1..])
        } else {
            eval_in_out(x, &direct)
        }
    };
    let mut kernel = Mlp::new(&imp.mlp, StorageDtype::F32).unwrap();
    for s in 0..20u64 {
        let x = random(300 + s, n, 3.0);
        let want = eval(&x) as f32;
        assert_close(
            kernel.forward(&x),
            want,
            1e-5,
            1e-6,
            &format!("{form} sample {s}"),
        );
        assert_close(
            imp.mlp.forward_reference(&x)[0],
            want,
            1e-5,
            1e-6,
            &format!("{form} ref {s}"),
        );
    }
}

#[test]
fn gemm_trans_b_1_imports() {
    check_synthetic("gemm", 1, 1.0, 1.0, false, false);
}

#[test]
fn gemm_trans_b_0_with_alpha_beta_and_float_data_imports() {
    check_synthetic("gemm", 0, 0.5, 2.0, true, false);
}

#[test]
fn gemm_with_diagonal_normaliser_imports() {
    check_synthetic("gemm", 1, 1.0, 1.0, false, true);
}

#[test]
fn matmul_add_chain_with_normaliser_imports() {
    check_synthetic("matmul_add", 0, 1.0, 1.0, false, true);
}

fn tiny_layers(
    n: usize,
) -> (
    Vec<onnx_protobuf::TensorProto>,
    Vec<onnx_protobuf::NodeProto>,
) {
    let inits = vec![
        tensor("w0", &[4, n], &random(1, 4 * n, 1.0), false),
        tensor("b0", &[4], &random(2, 4, 1.0), false),
        tensor("w1", &[1, 4], &random(3, 4, 1.0), false),
        tensor("b1", &[1], &random(4, 1, 1.0), false),
    ];
    let nodes = vec![
        node(
            "Gemm",
            "g0",
            &["input", "w0", "b0"],
            &["h0"],
            vec![attr_i("transB", 1)],
        ),
        node("Relu", "r0", &["h0"], &["r0"], vec![]),
        node(
            "Gemm",
            "g1",
            &["r0", "w1", "b1"],
            &["output"],
            vec![attr_i("transB", 1)],
        ),
    ];
    (inits, nodes)
}

#[test]
fn unsupported_op_is_named_with_its_node() {
    let (inits, mut nodes) = tiny_layers(3);
    nodes[1] = node("Tanh", "/act/Tanh_7", &["h0"], &["r0"], vec![]);
    let err = onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output"], 13))).unwrap_err();
    assert!(
        matches!(&err, OnnxError::UnsupportedOp { op_type, node } if op_type == "Tanh" && node == "/act/Tanh_7"),
        "{err}"
    );
    let msg = err.to_string();
    assert!(msg.contains("Tanh") && msg.contains("/act/Tanh_7"), "{msg}");
}

#[test]
fn branching_graph_is_not_a_chain() {
    let (mut inits, mut nodes) = tiny_layers(3);
    inits.push(tensor("w2", &[4, 3], &random(5, 12, 1.0), false));
    nodes.push(node(
        "Gemm",
        "side",
        &["input", "w2"],
        &["side_out"],
        vec![attr_i("transB", 1)],
    ));
    let err = onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output"], 13))).unwrap_err();
    assert!(matches!(err, OnnxError::NotAChain(_)), "{err}");
    assert!(err.to_string().contains("side"), "{err}");
}

#[test]
fn two_outputs_are_refused() {
    let (inits, nodes) = tiny_layers(3);
    let err =
        onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output", "h0"], 13))).unwrap_err();
    assert!(
        matches!(err, OnnxError::OutputCount { found: 2, .. }),
        "{err}"
    );
}

#[test]
fn non_float_input_and_weights_are_refused() {
    let (inits, nodes) = tiny_layers(3);
    let mut m = model(nodes, inits, 3, &["output"], 13);
    m.graph.as_mut().unwrap().input[0] =
        value_info("input", 3, onnx_protobuf::tensor_proto::DataType::DOUBLE);
    let err = onnx::import_bytes(&bytes(&m)).unwrap_err();
    assert!(
        matches!(&err, OnnxError::NonFloat { elem_type, .. } if elem_type == "DOUBLE"),
        "{err}"
    );

    let (mut inits, nodes) = tiny_layers(3);
    inits[0].data_type = onnx_protobuf::tensor_proto::DataType::FLOAT16 as i32;
    let err = onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output"], 13))).unwrap_err();
    assert!(
        matches!(&err, OnnxError::NonFloat { name, .. } if name == "w0"),
        "{err}"
    );
}

#[test]
fn old_opset_and_garbage_are_refused() {
    let (inits, nodes) = tiny_layers(3);
    let err = onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output"], 11))).unwrap_err();
    assert!(matches!(err, OnnxError::Opset { found: 11 }), "{err}");
    let err = onnx::import_bytes(b"\xff\xff\xff\xff not a protobuf").unwrap_err();
    assert!(matches!(err, OnnxError::Decode(_)), "{err}");
}

#[test]
fn missing_relu_between_layers_is_refused() {
    let (inits, mut nodes) = tiny_layers(3);
    nodes.remove(1);
    nodes[1].input[0] = "h0".into();
    let err = onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output"], 13))).unwrap_err();
    // 3 → 4 is not square, so it cannot be a normaliser either.
    assert!(err.to_string().contains("g0"), "{err}");
}

#[test]
fn wrong_weight_orientation_is_refused() {
    let (mut inits, nodes) = tiny_layers(3);
    inits[0].dims = vec![3, 4]; // claims [in, out] while transB = 1 expects [out, in]
    let err = onnx::import_bytes(&bytes(&model(nodes, inits, 3, &["output"], 13))).unwrap_err();
    assert!(
        matches!(&err, OnnxError::Node { node, .. } if node == "g0"),
        "{err}"
    );
}

fn with_leading_square(off_diag: f32) -> Vec<u8> {
    let n = 3;
    let (mut inits, mut nodes) = tiny_layers(n);
    let mut w = vec![0f32; 9];
    w[0] = 2.0;
    w[4] = 0.5;
    w[8] = 4.0;
    w[1] = off_diag;
    inits.push(tensor("nw", &[3, 3], &w, false));
    inits.push(tensor("nb", &[3], &[0.1, -0.2, 0.3], false));
    nodes[0].input[0] = "n0".into();
    nodes.insert(
        0,
        node(
            "Gemm",
            "/0/Gemm",
            &["input", "nw", "nb"],
            &["n0"],
            vec![attr_i("transB", 1)],
        ),
    );
    bytes(&model(nodes, inits, n, &["output"], 12))
}

#[test]
fn diagonal_normaliser_is_folded_with_scale_and_mean() {
    let imp = onnx::import_bytes(&with_leading_square(0.0)).unwrap();
    assert_eq!(imp.mlp.sizes(), vec![3, 4, 1]);
    assert_eq!(imp.mlp.norm.scale, vec![0.5, 2.0, 0.25]);
    // mean = −b·scale
    assert_eq!(imp.mlp.norm.mean, vec![-0.05, 0.4, -0.075]);
    // Below 1e-12 relative to the largest diagonal (4.0) counts as zero.
    assert!(onnx::import_bytes(&with_leading_square(1e-13)).is_ok());
    let err = onnx::import_bytes(&with_leading_square(1e-6)).unwrap_err();
    assert!(
        matches!(err, OnnxError::NotDiagonal { row: 0, col: 1, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("/0/Gemm"), "{err}");
}

#[test]
fn constant_nodes_and_identity_are_accepted() {
    let (mut inits, mut nodes) = tiny_layers(3);
    let b0 = inits.remove(1);
    let mut value = onnx_protobuf::AttributeProto::new();
    value.name = "value".into();
    value.type_ = onnx_protobuf::attribute_proto::AttributeType::TENSOR.into();
    value.t = protobuf::MessageField::some(b0.clone());
    nodes.insert(0, node("Constant", "c", &[], &["b0"], vec![value]));
    nodes[2] = node("Relu", "r0", &["h0"], &["rr"], vec![]);
    nodes.insert(3, node("Identity", "id", &["rr"], &["r0"], vec![]));
    let m = model(nodes, inits, 3, &["output"], 13);
    let imp = onnx::import_bytes(&bytes(&m)).unwrap();
    assert_eq!(imp.mlp.sizes(), vec![3, 4, 1]);
    assert_eq!(imp.mlp.layers[0].bias, random(2, 4, 1.0));
}

fn random_mlp(seed: u64, sizes: &[usize]) -> MlpWeights {
    seeded_mlp(&RandomMlpSpec::new(sizes), seed).unwrap()
}

#[test]
fn export_then_import_round_trips() {
    for sizes in [vec![6usize, 1], vec![10, 16, 1], vec![40, 32, 24, 8, 1]] {
        let mlp = random_mlp(sizes.len() as u64, &sizes);
        // Sub/Div keeps everything bit-exact.
        let b = onnx::export_bytes(&mlp, &ExportOptions::default()).unwrap();
        let imp = onnx::import_bytes(&b).unwrap();
        assert_eq!(imp.mlp, mlp, "sizes {sizes:?}");
        assert_eq!(imp.opset, onnx::EXPORT_OPSET);
        assert_eq!(
            (imp.input_name.as_str(), imp.output_name.as_str()),
            ("input", "output")
        );
        // The authors' diagonal Gemm: layers exact, statistics within f32 inversion error.
        let opts = ExportOptions {
            norm: NormExport::DiagonalGemm,
            metadata: vec![("k".into(), "v".into())],
        };
        let imp = onnx::import_bytes(&onnx::export_bytes(&mlp, &opts).unwrap()).unwrap();
        assert_eq!(imp.mlp.layers, mlp.layers);
        assert_eq!(imp.metadata.get("k").map(String::as_str), Some("v"));
        for i in 0..mlp.n_inputs() {
            assert_close(imp.mlp.norm.scale[i], mlp.norm.scale[i], 1e-6, 0.0, "scale");
            assert_close(imp.mlp.norm.mean[i], mlp.norm.mean[i], 1e-6, 1e-7, "mean");
        }
    }
}

#[test]
fn exported_graph_has_the_documented_interface() {
    let mlp = random_mlp(7, &[8, 5, 1]);
    let b = onnx::export_bytes(&mlp, &ExportOptions::default()).unwrap();
    let m = onnx_protobuf::ModelProto::parse_from_bytes(&b).unwrap();
    let g = m.graph.as_ref().unwrap();
    let ops: Vec<&str> = g.node.iter().map(|n| n.op_type.as_str()).collect();
    assert_eq!(ops, ["Sub", "Div", "Gemm", "Relu", "Gemm"]);
    assert_eq!(m.opset_import[0].version, 13);
    assert_eq!(g.input[0].name, "input");
    assert_eq!(g.output[0].name, "output");
    // The identity normalisation is not written at all.
    let mut plain = mlp.clone();
    plain.norm = Normalisation::identity(8);
    let m = onnx_protobuf::ModelProto::parse_from_bytes(
        &onnx::export_bytes(&plain, &ExportOptions::default()).unwrap(),
    )
    .unwrap();
    assert_eq!(m.graph.as_ref().unwrap().node.len(), 3);
    let imp = onnx::import_bytes(&m.write_to_bytes().unwrap()).unwrap();
    assert!(!imp.normalisation_found);
    assert_eq!(imp.mlp, plain);
}

#[test]
fn anchor_round_trips_through_our_export() {
    let imp = onnx::import_file(&anchor_onnx()).unwrap();
    let json = anchor_json();
    for norm in [NormExport::SubDiv, NormExport::DiagonalGemm] {
        let b = onnx::export_bytes(
            &imp.mlp,
            &ExportOptions {
                norm,
                metadata: vec![],
            },
        )
        .unwrap();
        let back = onnx::import_bytes(&b).unwrap();
        assert_eq!(back.mlp.layers, imp.mlp.layers);
        let mut k = Mlp::new(&back.mlp, StorageDtype::F32).unwrap();
        for c in json["cases"].as_array().unwrap() {
            let want = c["output"].as_f64().unwrap() as f32;
            assert_close(
                k.forward(&f32s(&c["input"])),
                want,
                RTOL,
                ATOL,
                c["name"].as_str().unwrap(),
            );
        }
    }
}

#[test]
fn missing_file_error_names_the_path() {
    let err = onnx::import_file(std::path::Path::new("/nonexistent/model.onnx")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/model.onnx"), "{err}");
}

#!/usr/bin/env python3
"""Reference vectors for the ONNX importer (frictl::interop::onnx), computed with ONNX Runtime.

Writes, under OUT/onnx/:
  <name>.onnx + <name>.json   random MLPs in the graph forms PyTorch exporters produce:
                              leading diagonal normalisation Gemm or Sub/Div, Gemm with transB 0/1,
                              alpha/beta, MatMul+Add, raw_data and float_data initializers,
                              1-3 hidden layers, dynamic batch
  ergocub_extra.json          the real ergoCub model (tests/fixtures/ergocub) on extra random inputs

Each JSON: {"name", "model", "n_inputs", "hidden", "form", "inputs": [[...]], "outputs": [...]}.
Inputs are float32 values (exact in JSON), outputs come from ONNX Runtime (CPU, 1 thread, batched).

Usage: gen_onnx_refs.py --out DIR
"""

import argparse
import json
import pathlib
import sys

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper

REPO = pathlib.Path(__file__).resolve().parents[2]
ANCHOR = REPO / "tests" / "fixtures" / "ergocub" / "blf_jtc_ergoCubSN002_l_ankle_roll_pinn_2024-06"


def tensor(name, arr, float_data=False):
    arr = np.asarray(arr, dtype=np.float32)
    if float_data:
        return helper.make_tensor(name, TensorProto.FLOAT, arr.shape, arr.flatten().tolist())
    return numpy_helper.from_array(arr, name)  # raw_data


def io(name, width):
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, ["batch", width])


def build(name, rng, n_in, hidden, form, norm, float_data=False, alpha=1.0, beta=1.0, opset=13):
    """A random MLP n_in -> hidden... -> 1 as an ONNX graph of the given form.

    form: "gemm_t1" (Gemm transB=1), "gemm_t0" (Gemm transB=0), "matmul_add" (MatMul + Add)
    norm: None, "diag_gemm" (authors' folded normaliser) or "sub_div"
    """
    inits, nodes = [], []
    mean = rng.normal(0.0, 2.0, n_in).astype(np.float32)
    scale = np.exp(rng.uniform(-2.0, 3.0, n_in)).astype(np.float32)
    cur = "input"
    if norm == "diag_gemm":
        w = np.diag(1.0 / scale).astype(np.float32)
        b = (-mean / scale).astype(np.float32)
        inits += [tensor("norm.weight", w, float_data), tensor("norm.bias", b, float_data)]
        nodes.append(helper.make_node("Gemm", [cur, "norm.weight", "norm.bias"], ["n0"], name="/0/Gemm", transB=1))
        cur = "n0"
    elif norm == "sub_div":
        inits += [tensor("mean", mean, float_data), tensor("scale", scale, float_data)]
        nodes.append(helper.make_node("Sub", [cur, "mean"], ["c0"], name="/norm/Sub"))
        nodes.append(helper.make_node("Div", ["c0", "scale"], ["n0"], name="/norm/Div"))
        cur = "n0"
    sizes = [n_in] + list(hidden) + [1]
    for k in range(len(sizes) - 1):
        i, o = sizes[k], sizes[k + 1]
        w = (rng.normal(0.0, 1.0, (o, i)) * np.sqrt(2.0 / i)).astype(np.float32)  # PyTorch [out, in]
        b = rng.normal(0.0, 0.1, o).astype(np.float32)
        wn, bn, out = f"l{k}.weight", f"l{k}.bias", ("output" if k == len(sizes) - 2 else f"h{k}")
        if form == "gemm_t1":
            inits += [tensor(wn, w, float_data), tensor(bn, b, float_data)]
            nodes.append(helper.make_node("Gemm", [cur, wn, bn], [out], name=f"/l{k}/Gemm",
                                          transB=1, alpha=alpha, beta=beta))
        elif form == "gemm_t0":
            inits += [tensor(wn, w.T.copy(), float_data), tensor(bn, b, float_data)]
            nodes.append(helper.make_node("Gemm", [cur, wn, bn], [out], name=f"/l{k}/Gemm",
                                          alpha=alpha, beta=beta))
        elif form == "matmul_add":
            inits += [tensor(wn, w.T.copy(), float_data), tensor(bn, b, float_data)]
            nodes.append(helper.make_node("MatMul", [cur, wn], [f"mm{k}"], name=f"/l{k}/MatMul"))
            nodes.append(helper.make_node("Add", [f"mm{k}", bn], [out], name=f"/l{k}/Add"))
        else:
            raise ValueError(form)
        cur = out
        if k < len(sizes) - 2:
            nodes.append(helper.make_node("Relu", [cur], [f"r{k}"], name=f"/relu{k}/Relu"))
            cur = f"r{k}"
    graph = helper.make_graph(nodes, name, [io("input", n_in)], [io("output", 1)], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)],
                              producer_name="gen_onnx_refs.py")
    model.ir_version = 7
    onnx.checker.check_model(model)
    return model, mean, scale


def session(model_bytes):
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    return ort.InferenceSession(model_bytes, so, providers=["CPUExecutionProvider"])


def run(sess, x):
    return sess.run(["output"], {"input": np.asarray(x, dtype=np.float32)})[0][:, 0]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, type=pathlib.Path)
    args = ap.parse_args()
    out = args.out / "onnx"
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(20240617)

    specs = [
        # name, n_in, hidden, form, norm, float_data, alpha, beta, opset
        ("gemm_t1_diagnorm_h1", 40, [64], "gemm_t1", "diag_gemm", False, 1.0, 1.0, 12),
        ("gemm_t0_nonorm_h2", 28, [48, 32], "gemm_t0", None, False, 1.0, 1.0, 13),
        ("matmul_add_diagnorm_h3", 50, [96, 40, 24], "matmul_add", "diag_gemm", False, 1.0, 1.0, 13),
        ("gemm_t1_alpha_beta_floatdata_h2", 41, [32, 16], "gemm_t1", "diag_gemm", True, 0.5, 2.0, 13),
        ("gemm_t0_alpha_floatdata_h1", 20, [24], "gemm_t0", None, True, 1.5, 0.25, 17),
        ("matmul_add_subdiv_h2", 44, [72, 36], "matmul_add", "sub_div", False, 1.0, 1.0, 13),
    ]
    for name, n_in, hidden, form, norm, float_data, alpha, beta, opset in specs:
        model, mean, scale = build(name, rng, n_in, hidden, form, norm, float_data, alpha, beta, opset)
        data = model.SerializeToString()
        (out / f"{name}.onnx").write_bytes(data)
        sess = session(data)
        # Raw inputs around the normaliser's statistics, plus exact zeros and the mean itself.
        z = rng.normal(0.0, 1.0, (14, n_in)).astype(np.float32)
        x = (mean + scale * z).astype(np.float32)
        x = np.vstack([x, np.zeros((1, n_in), np.float32), mean[None, :]]).astype(np.float32)
        y = run(sess, x)
        y1 = np.array([run(sess, row[None, :])[0] for row in x])  # batch-1 runs agree?
        assert np.allclose(y, y1, rtol=1e-6, atol=1e-7), name
        ref = {
            "name": name, "model": f"{name}.onnx", "n_inputs": n_in, "hidden": hidden, "form": form,
            "norm": norm, "float_data": float_data, "alpha": alpha, "beta": beta, "opset": opset,
            "generated_with": f"onnxruntime {ort.__version__} CPUExecutionProvider, 1 thread, float32",
            "inputs": [[float(v) for v in row] for row in x],
            "outputs": [float(v) for v in y],
        }
        (out / f"{name}.json").write_text(json.dumps(ref))
        print(f"wrote {out / name}.onnx/.json ({n_in} -> {hidden} -> 1, {form}, norm={norm})")

    # The real ergoCub model on extra random inputs.
    meta = json.loads(ANCHOR.with_suffix(".reference_io.json").read_text())
    mean = np.array(meta["normalisation_folded_in_first_Gemm"]["mean"], np.float32)
    scale = np.array(meta["normalisation_folded_in_first_Gemm"]["scale_iqr"], np.float32)
    sess = session(ANCHOR.with_suffix(".onnx").read_bytes())
    z = rng.normal(0.0, 1.0, (32, mean.size)).astype(np.float32)
    x = (mean + scale * z).astype(np.float32)
    y = run(sess, x)
    ref = {
        "name": "ergocub_extra", "model": str(ANCHOR.with_suffix(".onnx").name), "n_inputs": int(mean.size),
        "hidden": [450, 210, 280], "form": "gemm_t1", "norm": "diag_gemm",
        "generated_with": f"onnxruntime {ort.__version__} CPUExecutionProvider, 1 thread, float32",
        "inputs": [[float(v) for v in row] for row in x],
        "outputs": [float(v) for v in y],
    }
    (out / "ergocub_extra.json").write_text(json.dumps(ref))
    print(f"wrote {out / 'ergocub_extra.json'} (32 random inputs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Writes the inputs of the ONNX Runtime comparison bench (`benches/ort_compare.sh`).

- `paper.onnx` + `paper.raw`: a random paper-size PINN 40 -> 268 -> 215 -> 1 (seeded), exported the way
  PyTorch exports the authors' models: `Gemm(diagonal = folded normalisation) -> Gemm -> Relu -> Gemm ->
  Relu -> Gemm`, input `input` [batch, 40], output `output` [batch, 1].
- `ergocub.raw`: the weights of the real ergoCub ONNX model (`--ergocub`), extracted from its Gemm
  initializers, with the folded diagonal normalisation turned back into mean/scale.

Raw format (little endian), read by `benches/support/ort_cmp.rs`:
  b"FLRAW1\\0\\0", u32 n_sizes, u32 sizes[n_sizes], f32 mean[sizes[0]], f32 scale[sizes[0]],
  then per layer f32 weight[out][in] (PyTorch order) and f32 bias[out].
This is a bench fixture only, not the project's weight format (`.fwt`).
"""
import argparse
import os
import struct

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper


def write_raw(path, mean, scale, layers):
    sizes = [layers[0][0].shape[1]] + [w.shape[0] for w, _ in layers]
    with open(path, "wb") as f:
        f.write(b"FLRAW1\0\0")
        f.write(struct.pack("<I", len(sizes)))
        f.write(struct.pack(f"<{len(sizes)}I", *sizes))
        f.write(np.asarray(mean, "<f4").tobytes())
        f.write(np.asarray(scale, "<f4").tobytes())
        for w, b in layers:
            f.write(np.ascontiguousarray(w, "<f4").tobytes())
            f.write(np.asarray(b, "<f4").tobytes())


def paper_model(out_dir, seed=2024):
    rng = np.random.default_rng(seed)
    sizes = [40, 268, 215, 1]
    mean = rng.uniform(-0.5, 0.5, sizes[0]).astype(np.float32)
    scale = rng.uniform(0.5, 2.0, sizes[0]).astype(np.float32)
    layers = []
    for ni, no in zip(sizes[:-1], sizes[1:]):
        lim = np.sqrt(6.0 / ni)
        layers.append((rng.uniform(-lim, lim, (no, ni)).astype(np.float32), rng.uniform(-0.1, 0.3, no).astype(np.float32)))
    # Folded normalisation as PyTorch exports it: x_norm = x @ diag(1/scale) + (-mean/scale).
    w0 = np.diag(1.0 / scale).astype(np.float32)
    b0 = (-mean / scale).astype(np.float32)
    inits, nodes = [], []
    prev = "input"
    for k, (w, b) in enumerate([(w0, b0)] + layers):
        inits += [numpy_helper.from_array(w, f"w{k}"), numpy_helper.from_array(b, f"b{k}")]
        out = f"g{k}"
        nodes.append(helper.make_node("Gemm", [prev, f"w{k}", f"b{k}"], [out], transB=1))
        prev = out
        if 1 <= k < len(layers):
            nodes.append(helper.make_node("Relu", [out], [f"r{k}"]))
            prev = f"r{k}"
    nodes[-1].output[0] = "output"
    graph = helper.make_graph(
        nodes,
        "paper_pinn",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, ["batch", sizes[0]])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, ["batch", 1])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="frictionless-bench")
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, os.path.join(out_dir, "paper.onnx"))
    write_raw(os.path.join(out_dir, "paper.raw"), mean, scale, layers)


def extract_ergocub(onnx_path, out_path):
    m = onnx.load(onnx_path)
    inits = {t.name: numpy_helper.to_array(t).astype(np.float32) for t in m.graph.initializer}
    gemms = []
    for n in m.graph.node:
        if n.op_type != "Gemm":
            assert n.op_type == "Relu", f"unexpected op {n.op_type}"
            continue
        attrs = {a.name: helper.get_attribute_value(a) for a in n.attribute}
        assert attrs.get("alpha", 1.0) == 1.0 and attrs.get("beta", 1.0) == 1.0 and not attrs.get("transA", 0)
        w = inits[n.input[1]]
        if not attrs.get("transB", 0):
            w = w.T  # stored [in][out]: make it PyTorch [out][in]
        gemms.append((np.ascontiguousarray(w), inits[n.input[2]]))
    w0, b0 = gemms[0]
    d = np.diag(w0)
    assert np.count_nonzero(w0 - np.diag(d)) == 0, "first Gemm is not the folded diagonal normalisation"
    scale = (1.0 / d.astype(np.float64)).astype(np.float32)
    mean = (-b0.astype(np.float64) * scale).astype(np.float32)
    write_raw(out_path, mean, scale, gemms[1:])


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--ergocub", required=True, help="path of the ergoCub ONNX anchor")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    paper_model(a.out)
    extract_ergocub(a.ergocub, os.path.join(a.out, "ergocub.raw"))
    print(f"wrote paper.onnx, paper.raw, ergocub.raw to {a.out}")

#!/usr/bin/env python3
"""ONNX Runtime reference for GHNet inference speed (not part of `cargo test`).

Exports the shipped model (models/inference/weights/ghnet-epoch.safetensors, PyTorch names) to ONNX, built
with the `onnx` helper API from the weights: the same folded network ghnet runs (batch
norm folded into each kernel-1 conv in f64, the four fc layers collapsed into one affine
map in f64, tanh-form GELU), on inputs scaled by the model's `input_scale_mps`. Then:

1. checks ONNX Runtime's raw outputs against `ghnet forward` on the same velocities;
2. times ONNX Runtime on one thread (intra_op_num_threads=1): batch-256 throughput and
   single-sample latency (median of individually timed `run` calls from Python);
3. in the same run, runs `ghnet bench --json` (batch 256 `Network::forward`, single
   sample `Network::forward_one`, peak FMA loop) and prints a Markdown table with ratios.

Usage (from the repository root; needs `python3 -m pip install onnx onnxruntime numpy
safetensors`):

    python3 models/lab/benches/ort_reference.py [--seconds 2] [--onnx /tmp/ghnet-epoch.onnx]

The Rust side is built with `cargo build --release -p ghnet-lab --bin ghnet` unless
`--ghnet PATH` names a binary.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper
from safetensors import safe_open

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
K0 = np.sqrt(2.0 / np.pi)


def load(path):
    with safe_open(path, framework="np") as f:
        meta = f.metadata()
        tensors = {k: f.get_tensor(k).astype(np.float64) for k in f.keys()}
    return tensors, meta


def fold(t, meta):
    """Folded layers [(W [out,in], b [out], gelu?)] in f64, as ghnet's Network::fold."""
    arch = json.loads(meta["architecture"])
    eps = 1e-5
    layers = []
    for l in range(1, len(arch["conv"]) + 1):
        w = t[f"conv{l}.weight"][:, :, 0]
        scale = t[f"bn{l}.weight"] / np.sqrt(t[f"bn{l}.running_var"] + eps)
        b = scale * (t[f"conv{l}.bias"] - t[f"bn{l}.running_mean"]) + t[f"bn{l}.bias"]
        layers.append((w * scale[:, None], b, True))
    w, b = t["fc1.weight"], t["fc1.bias"]
    for l in range(2, len(arch["fc"]) + 2):
        wl, bl = t[f"fc{l}.weight"], t[f"fc{l}.bias"]
        w, b = wl @ w, wl @ b + bl
    layers.append((w, b, False))
    return layers


def gelu_nodes(x, name, opset):
    """Nodes computing tanh-form GELU of `x`; returns (nodes, initializers, output)."""
    if opset >= 20:
        return [helper.make_node("Gelu", [x], [name], approximate="tanh")], [], name
    c = lambda n, v: numpy_helper.from_array(np.array(v, np.float32), f"{name}_{n}")
    inits = [c("k1", 0.044715), c("k0", K0), c("half", 0.5), c("one", 1.0)]
    n = lambda op, ins, out: helper.make_node(op, ins, [f"{name}_{out}"])
    nodes = [
        n("Mul", [x, x], "x2"),
        n("Mul", [f"{name}_x2", x], "x3"),
        n("Mul", [f"{name}_x3", f"{name}_k1"], "a"),
        n("Add", [x, f"{name}_a"], "b"),
        n("Mul", [f"{name}_b", f"{name}_k0"], "u"),
        n("Tanh", [f"{name}_u"], "t"),
        n("Add", [f"{name}_t", f"{name}_one"], "p"),
        n("Mul", [x, f"{name}_half"], "h"),
        helper.make_node("Mul", [f"{name}_h", f"{name}_p"], [name]),
    ]
    return nodes, inits, name


def build_onnx(layers, opset):
    nodes, inits = [], []
    cur = "x"
    for i, (w, b, act) in enumerate(layers):
        inits.append(numpy_helper.from_array(w.T.astype(np.float32), f"w{i}"))
        inits.append(numpy_helper.from_array(b.astype(np.float32), f"b{i}"))
        z = f"z{i}" if act else "y"
        nodes.append(helper.make_node("Gemm", [cur, f"w{i}", f"b{i}"], [z]))
        cur = z
        if act:
            ns, ins, cur = gelu_nodes(z, f"g{i}", opset)
            nodes += ns
            inits += ins
    graph = helper.make_graph(
        nodes,
        "ghnet_folded",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["n", 2])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["n", layers[-1][0].shape[0]])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)])
    model.ir_version = min(model.ir_version, 10)
    onnx.checker.check_model(model)
    return model


def build_onnx_unfolded(t, meta, opset):
    """The network as PyTorch would export it: Conv1d (kernel 1) + BatchNormalization +
    GELU per layer on `[n, channels, 1]`, then the four fc layers as separate Gemms.
    ORT's graph optimiser folds what it can; this is the graph a user would hand it."""
    arch = json.loads(meta["architecture"])
    f32 = lambda a, n: numpy_helper.from_array(np.asarray(a, np.float32), n)
    inits = [numpy_helper.from_array(np.array([0, 2, 1], np.int64), "shape_in"),
             numpy_helper.from_array(np.array([0, -1], np.int64), "shape_flat")]
    nodes = [helper.make_node("Reshape", ["x", "shape_in"], ["c0"])]
    cur = "c0"
    for l in range(1, len(arch["conv"]) + 1):
        for k in ["conv%d.weight", "conv%d.bias", "bn%d.weight", "bn%d.bias",
                  "bn%d.running_mean", "bn%d.running_var"]:
            inits.append(f32(t[k % l], k % l))
        nodes.append(helper.make_node("Conv", [cur, f"conv{l}.weight", f"conv{l}.bias"],
                                      [f"conv{l}"], kernel_shape=[1]))
        nodes.append(helper.make_node(
            "BatchNormalization",
            [f"conv{l}", f"bn{l}.weight", f"bn{l}.bias", f"bn{l}.running_mean",
             f"bn{l}.running_var"], [f"bn{l}"], epsilon=1e-5))
        ns, ins, cur = gelu_nodes(f"bn{l}", f"act{l}", opset)
        nodes += ns
        inits += ins
    nodes.append(helper.make_node("Reshape", [cur, "shape_flat"], ["flat"]))
    cur = "flat"
    n_fc = len(arch["fc"]) + 1
    for l in range(1, n_fc + 1):
        inits += [f32(t[f"fc{l}.weight"], f"fc{l}.weight"), f32(t[f"fc{l}.bias"], f"fc{l}.bias")]
        out = "y" if l == n_fc else f"fc{l}"
        nodes.append(helper.make_node("Gemm", [cur, f"fc{l}.weight", f"fc{l}.bias"], [out],
                                      transB=1))
        cur = out
    graph = helper.make_graph(
        nodes,
        "ghnet_unfolded",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["n", 2])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["n", arch["output"]])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)])
    model.ir_version = min(model.ir_version, 10)
    onnx.checker.check_model(model)
    return model


def session(model_bytes):
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(model_bytes, so, providers=["CPUExecutionProvider"])


def velocities(n):
    i = np.arange(n)
    a = (i * 0.618).astype(np.float32)
    s = (0.05 + (i % 97) * 0.1).astype(np.float32)
    return s * np.cos(a), s * np.sin(a)


def rate(seconds, work, f):
    """Median units/s over rounds of ~20 ms, after a warm-up."""
    t, calls = time.perf_counter(), 0
    while time.perf_counter() - t < 0.02:
        f()
        calls += 1
    rates, end = [], time.perf_counter() + seconds
    while len(rates) < 5 or time.perf_counter() < end:
        t = time.perf_counter()
        for _ in range(calls):
            f()
        rates.append(work * calls / (time.perf_counter() - t))
    return statistics.median(rates)


def latency_us(seconds, f):
    for _ in range(2000):
        f()
    lat, end = [], time.perf_counter() + seconds
    while len(lat) < 1000 or time.perf_counter() < end:
        t = time.perf_counter()
        f()
        lat.append((time.perf_counter() - t) * 1e6)
    return statistics.median(lat)


def ghnet(args, cmd, stdin=None):
    exe = args.ghnet or os.path.join(ROOT, "target", "release", "ghnet")
    if not args.ghnet:
        subprocess.run(
            ["cargo", "build", "--release", "-q", "-p", "ghnet-inference", "--bin", "ghnet"],
            cwd=ROOT,
            check=True,
        )
    return subprocess.run(
        [exe] + cmd, input=stdin, capture_output=True, text=True, check=True
    ).stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", default=os.path.join(ROOT, "models", "inference", "weights", "ghnet-epoch.safetensors"))
    ap.add_argument("--seconds", type=float, default=2.0, help="per measurement")
    ap.add_argument("--onnx", help="also write the ONNX model here")
    ap.add_argument("--opset", type=int, default=20, help="20 uses the Gelu op; 17 spells it out")
    ap.add_argument("--ghnet", help="path of a built ghnet binary")
    args = ap.parse_args()

    t, meta = load(args.weights)
    if meta.get("activation") != "gelu_tanh":
        sys.exit(f"unsupported activation {meta.get('activation')}")
    scale = float(meta["input_scale_mps"])
    layers = fold(t, meta)
    macs = sum(w.shape[0] * w.shape[1] for w, _, _ in layers)
    folded = build_onnx(layers, args.opset)
    unfolded = build_onnx_unfolded(t, meta, args.opset)
    if args.onnx:
        onnx.save(folded, args.onnx)
    graphs = {"folded": session(folded.SerializeToString()),
              "unfolded": session(unfolded.SerializeToString())}

    # 1. Same outputs: ORT on scaled inputs vs `ghnet forward` on the velocities.
    vn, ve = velocities(4096)
    x = (np.stack([vn, ve], axis=1) / np.float32(scale)).astype(np.float32)
    ours_text = ghnet(
        args, ["forward", "--model", args.weights],
        stdin="".join(f"{a!r} {b!r}\n" for a, b in zip(vn[:512].tolist(), ve[:512].tolist())),
    )
    ours = np.array([[float(v) for v in l.split()] for l in ours_text.splitlines()])
    for name, sess in graphs.items():
        theirs = sess.run(None, {"x": x[:512]})[0].astype(np.float64)
        diff = np.abs(ours - theirs).max()
        size = np.abs(theirs).max()
        print(f"raw outputs, 512 samples, {name} graph: max |ghnet - ORT| = {diff:.2e} "
              f"(max |output| {size:.2f})")
        if not diff <= 1e-4 * max(1.0, size):
            sys.exit("ghnet and ONNX Runtime disagree")

    # 2. ORT timings, one thread.
    xb, x1 = np.ascontiguousarray(x[:256]), np.ascontiguousarray(x[:1])
    ort_batch, ort_single = {}, {}
    for name, sess in graphs.items():
        ort_batch[name] = rate(args.seconds, 256, lambda: sess.run(None, {"x": xb}))
        ort_single[name] = latency_us(args.seconds, lambda: sess.run(None, {"x": x1}))

    # 3. Ours, same run.
    r = json.loads(ghnet(args, ["bench", "--json", "--seconds", str(args.seconds),
                                "--model", args.weights]))
    peak = r["peak_gflops"]
    gf = lambda sps: sps * 2 * macs / 1e9
    print(f"\nONNX Runtime {ort.__version__} (opset {args.opset}, 1 thread) vs ghnet "
          f"({r['kernel']} kernel); {macs} MACs/sample, 2 FLOPs each; "
          f"peak FMA loop {peak:.1f} GFLOP/s (same run)\n")
    print("ORT graphs: *unfolded* is the PyTorch-style export (Conv1d + BatchNormalization + "
          "Gelu per layer, four Gemm fc layers); *folded* is the network ghnet runs (batch "
          "norm folded in f64, fc collapsed: one Gemm per layer, tanh Gelu).\n")
    b = r["batch256_samples_per_s"]
    s = r["single_median_us"]
    print("| measurement | ORT unfolded | ORT folded | ghnet | ghnet / ORT unfolded | ghnet / ORT folded |")
    print("|---|---|---|---|---|---|")
    print(f"| batch 256, samples/s | {ort_batch['unfolded']:,.0f} | {ort_batch['folded']:,.0f} | "
          f"{b:,.0f} | {b / ort_batch['unfolded']:.2f}x | {b / ort_batch['folded']:.2f}x |")
    share = lambda sps: f"{gf(sps):.1f} ({100 * gf(sps) / peak:.0f}%)"
    print(f"| batch 256, GFLOP/s (share of peak) | {share(ort_batch['unfolded'])} | "
          f"{share(ort_batch['folded'])} | {share(b)} | | |")
    print(f"| single sample, median latency (ORT: `run` from Python) | "
          f"{ort_single['unfolded']:.2f} µs | {ort_single['folded']:.2f} µs | {s:.2f} µs | "
          f"{ort_single['unfolded'] / s:.1f}x | {ort_single['folded'] / s:.1f}x |")
    print(f"| single sample, `Predictor::predict` (with head and status) | | | "
          f"{r['predictor_single_median_us']:.2f} µs | | |")
    print(f"| batch 256, `Predictor::predict_batch` | | | "
          f"{r['predictor_batch256_samples_per_s']:,.0f} samples/s | | |")


if __name__ == "__main__":
    main()

"""ONNX export of the surrogate.

* ``surrogate.onnx`` (plain, torch's exporter): ``x`` [batch, 3, n_features] -> ``y``
  [batch, n_outputs] kWh; the reference's LSTM with the output scaling folded in.
* ``surrogate_fast.onnx`` (structured, built with ``onnx.helper`` from the same weights):
  ``p`` [1, n_params] normalised parameters and ``xw`` [3, n_hours, n_hourly] (the hourly part of
  every window, step-major, built once per weather year) -> ``y`` [1, n_hours, n_outputs] kWh.
  The parameter part of the first layer's input projection is the same for every hour and step,
  so ``W_p . p + b_ih`` is computed once per proposal and passed to ONNX's fused LSTM kernel as
  its bias; the LSTM multiplies only the hourly features. Same numbers as the plain graph.
* ``surrogate_fused.onnx`` / ``surrogate_fused_int8.onnx`` (``fused.py``): the LSTM written out
  per step so the arithmetic shared by overlapping windows is done once, chunked over hours so
  every intermediate stays in cache; ``p`` [1, n_params] and ``xw`` [n_chunks, chunk + 2,
  n_hourly] -> ``y`` [n_chunks, chunk, n_outputs] kWh. The evaluator's default (float) and its
  int8 option (per-column int8 weights, VNNI); the int8 error against float is measured by the
  trainer and recorded in surrogate.json.
* ``surrogate_vjp.onnx`` (``fused.build_fused_vjp``): ``p``, ``xw`` as the fused graph's and a
  cotangent ``v`` [n_chunks, chunk, n_outputs] -> ``g`` [1, n_params] = ``v . dy/dp``: the
  gradient of any function of the outputs through the surrogate (gradient-based samplers and
  optimisers); checked against torch autograd by the trainer.
"""

import os
import warnings

import numpy as np
import onnx
import torch
from onnx import TensorProto, helper, numpy_helper

from . import LOOKBACK
from .fused import CHUNK, build_fused, build_fused_vjp, chunked_hourly
from .model import Denormalised

OPSET = 17
PLAIN = "surrogate.onnx"
FAST = "surrogate_fast.onnx"
FUSED = "surrogate_fused.onnx"
FUSED_INT8 = "surrogate_fused_int8.onnx"
VJP = "surrogate_vjp.onnx"
# torch gate blocks (i, f, g, o) -> ONNX LSTM order (i, o, f, c)
ONNX_GATES = [0, 3, 1, 2]


def _gates(a, hidden):
    """Reorders the 4*hidden gate axis (axis 0) from torch to ONNX order."""
    blocks = [a[k * hidden : (k + 1) * hidden] for k in range(4)]
    return np.concatenate([blocks[k] for k in ONNX_GATES], axis=0)


def export_plain(model, n_features, scale, nonnegative, path):
    plain = Denormalised(model, scale, nonnegative).eval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(plain, (torch.zeros(2, LOOKBACK, n_features),), path, dynamo=False,
                          opset_version=OPSET, input_names=["x"], output_names=["y"],
                          dynamic_axes={"x": {0: "batch"}, "y": {0: "batch"}}, do_constant_folding=True)


def build_fast(model, n_params, n_hourly, scale, nonnegative):
    """The structured graph (see the module doc) as an ``onnx.ModelProto``."""
    lstm = model.lstm
    H = lstm.hidden_size
    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)
    sd = {k: v.detach().cpu().numpy().astype(np.float64) for k, v in lstm.state_dict().items()}
    w_ih0 = _gates(sd["weight_ih_l0"], H)
    # A ScheduledSurrogate calibrating no schedule parameter: its schedule term q is 0 and its
    # weight column (the last) unused.
    unused_q = hasattr(model, "sched_params") and model.sched_params.shape[0] == 0
    w_hourly = w_ih0[None, :, n_params:w_ih0.shape[1] - unused_q]
    inits = [
        numpy_helper.from_array(f32(w_ih0[:, :n_params].T), "w_p"),
        numpy_helper.from_array(f32(_gates(sd["bias_ih_l0"], H)[None, :]), "b_ih0"),
        numpy_helper.from_array(f32(_gates(sd["bias_hh_l0"], H)[None, :]), "b_hh0"),
        numpy_helper.from_array(f32(w_hourly), "w_0"),
        numpy_helper.from_array(f32(_gates(sd["weight_hh_l0"], H)[None]), "r_0"),
        numpy_helper.from_array(np.array([1], dtype=np.int64), "axis1"),
        numpy_helper.from_array(f32(model.head.weight.detach().cpu().numpy().T), "w_fc"),
        numpy_helper.from_array(f32(model.head.bias.detach().cpu().numpy()), "b_fc"),
        numpy_helper.from_array(f32(scale), "scale"),
    ]
    nodes = [
        helper.make_node("MatMul", ["p", "w_p"], ["pp"], name="param_projection"),
        helper.make_node("Add", ["pp", "b_ih0"], ["pb"]),
        helper.make_node("Concat", ["pb", "b_hh0"], ["bias0"], axis=1),
    ]
    x0 = "xw"
    if hasattr(model, "sched_params") and model.sched_params.shape[0] > 0:
        # ScheduledSurrogate: the schedule term q = m . (width * p[sched_params]) as one more
        # input column (the LSTM's last weight column is its).
        k = model.sched_params.shape[0]
        inits += [
            numpy_helper.from_array(model.sched_params.cpu().numpy().astype(np.int64), "sched_idx"),
            numpy_helper.from_array(f32(model.sched_width.cpu().numpy()[None]), "sched_width"),
            numpy_helper.from_array(np.array([n_hourly - k], dtype=np.int64), "sched_start"),
            numpy_helper.from_array(np.array([n_hourly], dtype=np.int64), "sched_end"),
            numpy_helper.from_array(np.array([2], dtype=np.int64), "axis2"),
        ]
        nodes += [
            helper.make_node("Gather", ["p", "sched_idx"], ["sched_sel"], axis=1),
            helper.make_node("Mul", ["sched_sel", "sched_width"], ["sched_pb"]),
            helper.make_node("Transpose", ["sched_pb"], ["sched_pbt"]),
            helper.make_node("Slice", ["xw", "sched_start", "sched_end", "axis2"], ["sched_m"]),
            helper.make_node("MatMul", ["sched_m", "sched_pbt"], ["sched_q"]),
            helper.make_node("Concat", ["xw", "sched_q"], ["xwq"], axis=2),
        ]
        x0 = "xwq"
    nodes += [
        helper.make_node("LSTM", [x0, "w_0", "r_0", "bias0"], ["y0", "", ""], hidden_size=H),
        helper.make_node("Squeeze", ["y0", "axis1"], ["x1"]),
    ]
    x = "x1"
    for k in range(1, lstm.num_layers):
        b = np.concatenate([_gates(sd[f"bias_ih_l{k}"], H), _gates(sd[f"bias_hh_l{k}"], H)])[None]
        inits += [
            numpy_helper.from_array(f32(_gates(sd[f"weight_ih_l{k}"], H)[None]), f"w_{k}"),
            numpy_helper.from_array(f32(_gates(sd[f"weight_hh_l{k}"], H)[None]), f"r_{k}"),
            numpy_helper.from_array(f32(b), f"b_{k}"),
        ]
        last = k == lstm.num_layers - 1
        outs = ["", f"h{k}", ""] if last else [f"y{k}", "", ""]
        nodes.append(helper.make_node("LSTM", [x, f"w_{k}", f"r_{k}", f"b_{k}"], outs, hidden_size=H))
        if not last:
            nodes.append(helper.make_node("Squeeze", [f"y{k}", "axis1"], [f"x{k + 1}"]))
            x = f"x{k + 1}"
    last_h = f"h{lstm.num_layers - 1}"  # [1, T, H]: the last step of every window
    nodes += [
        helper.make_node("Relu", [last_h], ["hr"]),
        helper.make_node("MatMul", ["hr", "w_fc"], ["z0"]),
        helper.make_node("Add", ["z0", "b_fc"], ["z"]),
    ]
    if nonnegative:
        nodes.append(helper.make_node("Relu", ["z"], ["zr"]))
        nodes.append(helper.make_node("Mul", ["zr", "scale"], ["y"]))
    else:
        nodes.append(helper.make_node("Mul", ["z", "scale"], ["y"]))
    if lstm.num_layers == 1:
        raise ValueError("the fast graph needs at least 2 LSTM layers")
    graph = helper.make_graph(
        nodes, "bemcal_surrogate_fast",
        [helper.make_tensor_value_info("p", TensorProto.FLOAT, [1, n_params]),
         helper.make_tensor_value_info("xw", TensorProto.FLOAT, [LOOKBACK, "hours", n_hourly])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, "hours", len(scale)])],
        initializer=inits)
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="bemcal_train")
    m.ir_version = 8  # opset 17 era; readable by every onnxruntime bemcal supports
    onnx.checker.check_model(m)
    return m


def export_all(model, n_params, n_hourly, scale, nonnegative, out_dir):
    """Writes the graphs into ``out_dir``; returns their file names (int8 only when
    onnxruntime's quantiser is available)."""
    model = model.cpu().eval()
    export_plain(model, n_params + n_hourly, scale, nonnegative, os.path.join(out_dir, PLAIN))
    onnx.save(build_fast(model, n_params, n_hourly, scale, nonnegative), os.path.join(out_dir, FAST))
    files = {"plain": PLAIN, "fast": FAST}
    if model.lstm.num_layers == 2:
        for key, name, int8 in (("fused", FUSED, False), ("fused_int8", FUSED_INT8, True)):
            onnx.save(build_fused(model, n_params, n_hourly, scale, nonnegative, int8=int8),
                      os.path.join(out_dir, name))
            files[key] = name
        onnx.save(build_fused_vjp(model, n_params, n_hourly, scale, nonnegative), os.path.join(out_dir, VJP))
        files["vjp"] = VJP
    return files


def vjp_check(model, out_dir, vjp_file, p_row, hourly, scale, nonnegative, seed=0):
    """max |g_onnx - g_torch| / max |g_torch| for the VJP graph at parameter row ``p_row``
    (normalised) with a random cotangent over the year: ``g_torch`` from autograd through the
    plain model. None without onnxruntime."""
    try:
        import onnxruntime as ort
    except ImportError:
        return None
    T, n_p = hourly.shape[0], len(p_row)
    v = np.random.default_rng(seed).normal(size=(T, len(scale))).astype(np.float32)
    pt = torch.tensor(np.asarray(p_row, dtype=np.float32), requires_grad=True)
    idx = np.maximum(np.arange(T)[:, None] - (LOOKBACK - 1) + np.arange(LOOKBACK)[None], 0)
    x = torch.cat([pt[None, None, :].expand(T, LOOKBACK, n_p),
                   torch.as_tensor(hourly[idx], dtype=torch.float32)], dim=2)
    y = Denormalised(model.cpu().eval(), scale, nonnegative)(x)
    (y * torch.as_tensor(v)).sum().backward()
    ref = pt.grad.numpy()
    xc = chunked_hourly(hourly.astype(np.float32), CHUNK)
    vc = np.zeros((xc.shape[0] * CHUNK, v.shape[1]), np.float32)
    vc[:T] = v
    s = ort.InferenceSession(os.path.join(out_dir, vjp_file), providers=["CPUExecutionProvider"])
    g = s.run(["g"], {"p": pt.detach().numpy()[None], "xw": xc, "v": vc.reshape(xc.shape[0], CHUNK, -1)})[0][0]
    return float(np.max(np.abs(g - ref)) / max(float(np.max(np.abs(ref))), 1e-12))


def windows_step_major(hourly):
    """[3, n_hours, n_hourly]: step s of the window ending at hour t is hour max(t - 2 + s, 0)."""
    T = hourly.shape[0]
    return np.stack([hourly[np.maximum(np.arange(T) - (LOOKBACK - 1) + s, 0)] for s in range(LOOKBACK)])


def run_onnx(out_dir, files, x, p_rows, hourly, threads=1):
    """Runs the exported graphs in onnxruntime: plain on windows ``x``; fast and fused (float and
    int8) on the year for each parameter row. Returns None without onnxruntime."""
    try:
        import onnxruntime as ort
    except ImportError:
        return None
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    sess = lambda f: ort.InferenceSession(os.path.join(out_dir, f), so, providers=["CPUExecutionProvider"])
    xw = windows_step_major(hourly).astype(np.float32)
    res = {"plain": sess(files["plain"]).run(["y"], {"x": x.astype(np.float32)})[0]}
    if "fast" in files:
        s = sess(files["fast"])
        res["fast"] = np.stack([s.run(["y"], {"p": p[None].astype(np.float32), "xw": xw})[0][0] for p in p_rows])
    T = hourly.shape[0]
    xc = chunked_hourly(hourly.astype(np.float32), CHUNK)
    for key in ("fused", "fused_int8"):
        if key in files:
            s = sess(files[key])
            ys = [s.run(["y"], {"p": p[None].astype(np.float32), "xw": xc})[0] for p in p_rows]
            res[key] = np.stack([y.reshape(-1, y.shape[-1])[:T] for y in ys])
    return res


def add_vjp(out_dir):
    """Adds ``surrogate_vjp.onnx`` to a surrogate trained before the VJP graph existed (from its
    ``weights.pt``), checks it against autograd on random normalised inputs and records it in
    ``surrogate.json`` (``files.vjp``, ``onnxruntime_check.vjp_vs_torch``)."""
    import json

    from .model import Surrogate

    meta_path = os.path.join(out_dir, "surrogate.json")
    with open(meta_path) as f:
        meta = json.load(f)
    try:
        saved = torch.load(os.path.join(out_dir, "weights.pt"), map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise SystemExit(f"--add-vjp {out_dir}: no weights.pt there; retrain the surrogate")
    n_params, n_features = len(meta["params"]), int(meta["n_features"])
    model = Surrogate(n_features, len(saved["scale"]), meta["model"]["hidden"], meta["model"]["layers"])
    model.load_state_dict(saved["state_dict"])
    model.eval()
    scale, nonneg = np.asarray(saved["scale"]), bool(meta["nonnegative"])
    onnx.save(build_fused_vjp(model, n_params, n_features - n_params, scale, nonneg), os.path.join(out_dir, VJP))
    rng = np.random.default_rng(0)
    hourly = rng.normal(size=(3 * CHUNK + 7, n_features - n_params)).astype(np.float32)
    err = vjp_check(model, out_dir, VJP, rng.uniform(size=n_params), hourly, scale, nonneg)
    meta["files"]["vjp"] = VJP
    if not meta.get("onnxruntime_check"):
        meta["onnxruntime_check"] = {}
    meta["onnxruntime_check"]["vjp_vs_torch"] = err
    with open(meta_path, "w") as f:
        json.dump(meta, f, indent=1)
    print(f"wrote {os.path.join(out_dir, VJP)} (vs autograd: {err:.2e})")
    return err

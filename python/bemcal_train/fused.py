"""The fused surrogate graph (``surrogate_fused.onnx``, and ``surrogate_fused_int8.onnx``).

Inputs ``p`` [1, n_params] (normalised parameters) and ``xh`` [n_hours, n_hourly] (the hourly
rows of the weather year, normalised, NOT windowed) -> ``y`` [n_hours, n_outputs] kWh. The same
function as the plain graph, written out step by step so that the arithmetic the windows share
is done once:

* Window ``t`` visits hours ``(t-2, t-1, t)`` (clamped at 0), every window from a zero state.
  Step 1 of every window is "hour u from zero state" and step 2 is "hours (u-1, u) from zero
  state", so both are computed once per hour ``u`` and shifted into place (``prev(X)[u] =
  X[max(u - 1, 0)]``, one Gather); only step 3 is per window. That is ``n_hours`` rows per
  step, as in the plain graph, but:
* layer 1: the input projection is ``W_w . x_u + (W_p . p + b)``: the hourly part once per hour
  (K = n_hourly, cheap), the parameter part one vector per proposal (the Gemm's bias). Step 1
  has no recurrent product and no forget gate (``c = i * g``); steps 2-3 are one recurrent
  product each, accumulated onto that projection (Gemm ``C``).
* layer 2: step 1 has no recurrent product and no forget gate; steps 2-3 multiply
  ``[x; h_prev]`` (K = 2 * hidden) once per gate.
* One Gemm per gate with the gate's nonlinearity right after it (ONNX Runtime fuses the pair
  into ``FusedGemm``), so no [n_hours, 4 * hidden] tensor is ever split.

FLOPs (multiply-add = 2) per hour, H = hidden, F_h = n_hourly:
  2 * (4H * F_h + 2 * 4H * H + 3H * H + 2 * 4H * 2H + H * K) = 890,624 FLOP for H = 128, F_h = 5,
K = 3 (7.80 GFLOP per 8,760-hour evaluation, against 11.50 for the plain LSTM).

The int8 variant quantises the recurrent / layer-2 weights (K = H or 2H) per output column,
symmetric s8, and quantises each Gemm input once per step (``DynamicQuantizeLinear``, u8) for
``MatMulIntegerToFloat`` (AVX-512 VNNI / AVX-VNNI kernels in MLAS). The hourly projection, the
parameter projection and the head stay float.
"""

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from . import LOOKBACK

OPSET = 17
CHUNK = 256  # windows per chunk: every intermediate of a chunk stays in L2
# torch gate blocks: i, f, g, o
GATE = {"i": 0, "f": 1, "g": 2, "o": 3}
ACT = {"i": "Sigmoid", "f": "Sigmoid", "g": "Tanh", "o": "Sigmoid"}


def fused_flops_per_hour(n_hourly, hidden=128, n_out=3):
    H = hidden
    return 2 * (4 * H * n_hourly + 2 * 4 * H * H + 3 * H * H + 2 * 4 * H * 2 * H + H * n_out)


class _G:
    def __init__(self):
        self.nodes, self.inits, self.n = [], [], 0

    def name(self, base):
        self.n += 1
        return f"{base}_{self.n}"

    def init(self, name, a, dtype=np.float32):
        self.inits.append(numpy_helper.from_array(np.ascontiguousarray(a, dtype=dtype), name))
        return name

    def op(self, op, inputs, base=None, domain=None, **attrs):
        out = self.name(base or op.lower())
        self.nodes.append(helper.make_node(op, inputs, [out], name=out, domain=domain, **attrs))
        return out

    def gemm(self, a, w, base, act, c=None):
        """act(a @ w.T + c) with w [N, K] float64 numpy; c an initializer bias or a tensor."""
        wn = self.init(self.name("w"), w.T)
        out = self.op("Gemm", [a, wn, c] if c is not None else [a, wn], base=base)
        return self.op(act, [out]) if act else out


def _forward(model, n_params, scale, nonnegative, int8, chunk):
    """Builds the per-chunk forward pass into a fresh ``_G``; returns it with the intermediates
    the VJP needs (``t``: per layer and step the gate activations, ``c``, ``tanh c``, ``c_prev``;
    ``hr``, ``z``). The chunk body reads ``xc`` [R, n_hourly] and writes ``yc``; the nodes named
    ``param_projection``, ``pb*`` compute the per-proposal ``W_p . p + b`` outside it."""
    lstm = model.lstm
    H = lstm.hidden_size
    if lstm.num_layers != 2:
        raise ValueError("the fused graph is written for 2 LSTM layers")
    sd = {k: v.detach().cpu().numpy().astype(np.float64) for k, v in lstm.state_dict().items()}

    def blk(a, gate):
        k = GATE[gate]
        return a[k * H:(k + 1) * H]

    g = _G()
    R = chunk + LOOKBACK - 1  # rows per chunk: 2 warm-up hours + chunk windows
    idx = g.init("prev_idx", np.maximum(np.arange(R) - 1, 0), np.int64)

    def prev(x):
        return g.op("Gather", [x, idx], base="prev", axis=0)

    def qgemm(aq, w, act, bias=None):
        """act(dequant(aq) @ w.T + bias): aq = (q, scale, zero point) of the input."""
        s = np.maximum(np.abs(w).max(axis=1), 1e-12) / 127.0  # per output column
        q = np.clip(np.round(w / s[:, None]), -127, 127).astype(np.int8)
        ins = [aq[0], g.init(g.name("wq"), q.T, np.int8), aq[1], g.init(g.name("ws"), s),
               aq[2], g.init(g.name("wz"), np.zeros(len(s), np.int8), np.int8)]
        if bias is not None:
            ins.append(g.init(g.name("b"), bias))
        out = g.op("MatMulIntegerToFloat", ins, base="qgemm", domain="com.microsoft")
        return g.op(act, [out]) if act else out

    def quant(a):
        n = g.name("dq")
        outs = [n + "_q", n + "_s", n + "_z"]
        g.nodes.append(helper.make_node("DynamicQuantizeLinear", [a], outs, name=n))
        return outs

    def cell(gates, c_prev):
        """c = f * c_prev + i * g (or i * g from zero state); h = o * tanh(c)."""
        ig = g.op("Mul", [gates["i"], gates["g"]])
        c = ig if c_prev is None else g.op("Add", [g.op("Mul", [gates["f"], c_prev]), ig], base="c")
        tc = g.op("Tanh", [c])
        h = g.op("Mul", [gates["o"], tc], base="h")
        return h, {"gates": gates, "c": c, "tc": tc, "c_prev": c_prev}

    t = {1: [], 2: []}
    # ---- layer 1 ----
    w0 = sd["weight_ih_l0"]
    b0 = sd["bias_ih_l0"] + sd["bias_hh_l0"]
    pw = g.init("w_p", w0[:, :n_params].T)  # [n_params, 4H]
    pb = g.op("Add", [g.op("MatMul", ["p", pw], base="param_projection"), g.init("b_0", b0[None])], base="pb")
    splits = g.init("split4", np.array([H] * 4, dtype=np.int64), np.int64)
    pbs = [pb + f"_{k}" for k in "ifgo"]
    g.nodes.append(helper.make_node("Split", [pb, splits], pbs, name="pb_split", axis=1))
    pbg = dict(zip("ifgo", pbs))
    sched = schedule_term(g, model, n_params, w0)
    # The LSTM's inputs less the schedule term: a ScheduledSurrogate's last weight column is q's
    # (q = 0 where no schedule parameter is calibrated, its column then unused).
    n_in = w0.shape[1] - hasattr(model, "sched_params")
    if sched is not None:  # C = W_p . p + b + q w_q, q per row (ScheduledSurrogate)
        pbg = {k: g.op("Add", [pbg[k], g.op("MatMul", [sched["q"], g.init(g.name("wq"), blk(sched["w"], k).T)])])
               for k in "ifgo"}
    a0 = {k: g.gemm("xc", blk(w0[:, n_params:n_in], k), "a0", None, pbg[k]) for k in "ifgo"}
    r0 = sd["weight_hh_l0"]
    # step 1 (zero state)
    h, rec = cell({k: g.op(ACT[k], [a0[k]]) for k in "igo"}, None)
    t[1].append(rec)
    layer1 = [h]
    for _ in range(LOOKBACK - 1):
        hp, cp = prev(h), prev(rec["c"])
        if int8:
            hq = quant(hp)
            z = {k: g.op("Add", [qgemm(hq, blk(r0, k), None), a0[k]]) for k in "ifgo"}
            gates = {k: g.op(ACT[k], [z[k]]) for k in "ifgo"}
        else:
            gates = {k: g.gemm(hp, blk(r0, k), "z1", ACT[k], a0[k]) for k in "ifgo"}
        h, rec = cell(gates, cp)
        t[1].append(rec)
        layer1.append(h)
    # ---- layer 2 ----
    w1, r1 = sd["weight_ih_l1"], sd["weight_hh_l1"]
    b1 = sd["bias_ih_l1"] + sd["bias_hh_l1"]
    wr1 = np.concatenate([w1, r1], axis=1)  # [4H, 2H]: [x; h_prev]
    x = layer1[0]
    if int8:
        xq = quant(x)
        gates = {k: qgemm(xq, blk(w1, k), ACT[k], blk(b1, k)) for k in "igo"}
    else:
        gates = {k: g.gemm(x, blk(w1, k), "z2", ACT[k], g.init(g.name("b"), blk(b1, k))) for k in "igo"}
    h, rec = cell(gates, None)
    t[2].append(rec)
    for s in range(1, LOOKBACK):
        xs = g.op("Concat", [layer1[s], prev(h)], base="xh2", axis=1)
        cp = prev(rec["c"])
        if int8:
            xq = quant(xs)
            gates = {k: qgemm(xq, blk(wr1, k), ACT[k], blk(b1, k)) for k in "ifgo"}
        else:
            gates = {k: g.gemm(xs, blk(wr1, k), "z2", ACT[k], g.init(g.name("b"), blk(b1, k))) for k in "ifgo"}
        h, rec = cell(gates, cp)
        t[2].append(rec)
    # ---- head: relu -> linear -> (relu) ; kWh scale folded into the head (scale > 0) ----
    s = np.asarray(scale, dtype=np.float64)
    wfc = model.head.weight.detach().cpu().numpy().astype(np.float64) * s[:, None]
    bfc = model.head.bias.detach().cpu().numpy().astype(np.float64) * s
    hr = g.op("Slice", [h, g.init("two", [LOOKBACK - 1], np.int64), g.init("rows", [R], np.int64),
                        g.init("ax0", [0], np.int64)], base="windows")
    z = g.gemm(g.op("Relu", [hr]), wfc, "head", None, g.init("b_fc", bfc))
    g.nodes.append(helper.make_node("Relu" if nonnegative else "Identity", [z], ["yc"], name="out"))
    weights = {"w0": w0[:, :n_params], "r0": r0, "w1": w1, "wr1": wr1, "wfc": wfc}
    return g, {"t": t, "hr": hr, "z": z, "H": H, "R": R, "n_out": len(s), "weights": weights, "sched": sched}


def schedule_term(g, model, n_params, w0):
    """A ``ScheduledSurrogate``'s schedule term in the chunk body, or None for today's surrogate:
    ``pb_sched`` = width * p[sched_params] [1, K] per proposal (outside the Scan), the
    indicators ``m`` [R, K] (the last K columns of ``xc``) and ``q = m . pb_sched^T`` [R, 1];
    ``w`` [4H, 1] its LSTM weight column (the last)."""
    if not hasattr(model, "sched_params") or model.sched_params.shape[0] == 0:
        return None
    idx = model.sched_params.cpu().numpy().astype(np.int64)
    width = model.sched_width.cpu().numpy().astype(np.float64)
    k, n_hourly = len(idx), w0.shape[1] - 1 - n_params
    g.init("sched_idx", idx, np.int64)
    g.init("sched_width", width[None])
    sel = g.op("Gather", ["p", "sched_idx"], base="pb_sched_sel", axis=1)
    pbt = g.op("Transpose", [g.op("Mul", [sel, "sched_width"], base="pb_sched")], base="pb_sched_t")
    m = g.op("Slice", ["xc", g.init(g.name("s"), [n_hourly - k], np.int64), g.init(g.name("e"), [n_hourly], np.int64),
                       g.init(g.name("a"), [1], np.int64)], base="sched_m")
    q = g.op("MatMul", [m, pbt], base="sched_q")
    return {"m": m, "q": q, "w": w0[:, -1:], "k": k, "idx": idx, "width": width}


_OUTER = ("w_p", "b_0", "split4", "sched_idx", "sched_width")


def _split_outer(g):
    """(outer nodes, body nodes, outer initializers, body initializers): the per-proposal
    parameter projection stays outside the Scan, everything else is the chunk body."""
    outer_names = lambda n: n.name in ("param_projection", "pb", "pb_split") or \
        n.name.startswith("param_projection") or n.name.startswith("pb_")
    body = [n for n in g.nodes if not outer_names(n)]
    outer = [n for n in g.nodes if outer_names(n)]
    return (outer, body, [i for i in g.inits if i.name in _OUTER],
            [i for i in g.inits if i.name not in _OUTER])


def build_fused(model, n_params, n_hourly, scale, nonnegative, int8=False, chunk=CHUNK):
    """The fused graph (see the module doc) as an ``onnx.ModelProto``."""
    g, f = _forward(model, n_params, scale, nonnegative, int8, chunk)
    R, n_out = f["R"], f["n_out"]
    outer, body_nodes, outer_inits, body_inits = _split_outer(g)
    body = helper.make_graph(
        body_nodes, "chunk", [helper.make_tensor_value_info("xc", TensorProto.FLOAT, [R, n_hourly])],
        [helper.make_tensor_value_info("yc", TensorProto.FLOAT, [chunk, n_out])], initializer=body_inits)
    scan = helper.make_node("Scan", ["xw"], ["y"], name="chunks", body=body, num_scan_inputs=1)
    graph = helper.make_graph(
        outer + [scan], "bemcal_surrogate_fused" + ("_int8" if int8 else ""),
        [helper.make_tensor_value_info("p", TensorProto.FLOAT, [1, n_params]),
         helper.make_tensor_value_info("xw", TensorProto.FLOAT, ["chunks", R, n_hourly])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["chunks", chunk, n_out])],
        initializer=outer_inits)
    opsets = [helper.make_opsetid("", OPSET)]
    if int8:
        opsets.append(helper.make_opsetid("com.microsoft", 1))
    m = helper.make_model(graph, opset_imports=opsets, producer_name="bemcal_train")
    m.ir_version = 8
    if not int8:
        onnx.checker.check_model(m)
    return m


def build_fused_vjp(model, n_params, n_hourly, scale, nonnegative, chunk=CHUNK):
    """The vector-Jacobian product of the fused graph (``surrogate_vjp.onnx``): inputs ``p``
    [1, n_params] and ``xw`` as the fused graph's, and ``v`` [n_chunks, chunk, n_outputs] (a
    cotangent on ``y``, e.g. d ln L / dy in 1 / kWh, 0 on padding rows) -> ``g`` [1, n_params]
    = ``v . dy/dp`` (p normalised). The forward pass of each chunk, then reverse-mode
    differentiation written out by hand (no autograd in the graph): LSTM cell backward
    (c = f c' + i g, h = o tanh c; sigmoid' = s (1 - s), tanh' = 1 - t^2), the shared steps'
    ``prev`` Gather reversed (row u's gradient goes to row u - 1; row 0 also keeps row 1's), and
    the parameters' gradient accumulated at layer 1's input projection, the only place ``p``
    enters: ``g = W_p^T sum_(rows, steps) d a``. About 3 forward passes of arithmetic."""
    g, f = _forward(model, n_params, scale, nonnegative, False, chunk)
    H, R, n_out, t, W = f["H"], f["R"], f["n_out"], f["t"], f["weights"]
    one = g.init("one", np.array(1.0))
    axis0 = g.init("axis0", np.array([0], dtype=np.int64), np.int64)
    zero_row = g.init("zero_row", np.zeros((1, H)))
    e0 = g.init("e0", np.eye(R)[:, :1])  # [R, 1]: 1 at row 0
    sl = lambda x, a, b: g.op("Slice", [x, g.init(g.name("s"), [a], np.int64), g.init(g.name("e"), [b], np.int64),
                                        axis0], base="sl")
    add = lambda a, b: b if a is None else (a if b is None else g.op("Add", [a, b]))
    mul = lambda a, b: g.op("Mul", [a, b])
    dsig = lambda s: mul(s, g.op("Sub", [one, s]))
    dtanh = lambda th: g.op("Sub", [one, mul(th, th)])
    gates_w = lambda w, ks: np.concatenate([w[GATE[k] * H:(GATE[k] + 1) * H] for k in ks], axis=0)

    def mask(x):
        return g.op("Cast", [g.op("Greater", [x, g.init(g.name("zero"), np.array(0.0))])], to=TensorProto.FLOAT)

    def unprev(d):
        """Gradient w.r.t. X of prev(X)[u] = X[max(u - 1, 0)]."""
        shifted = g.op("Concat", [sl(d, 1, R), zero_row], axis=0)
        return g.op("Add", [shifted, mul(sl(d, 0, 1), e0)])

    def cell_back(rec, dh, dc_in):
        """(gate pre-activation gradients, dc_prev) of one cell."""
        gt = rec["gates"]
        do = mul(dh, rec["tc"])
        dc = add(mul(mul(dh, gt["o"]), dtanh(rec["tc"])), dc_in)
        da = {"o": mul(do, dsig(gt["o"])), "i": mul(mul(dc, gt["g"]), dsig(gt["i"])),
              "g": mul(mul(dc, gt["i"]), dtanh(gt["g"]))}
        dc_prev = None
        if rec["c_prev"] is not None:
            da["f"] = mul(mul(dc, rec["c_prev"]), dsig(gt["f"]))
            dc_prev = mul(dc, gt["f"])
        return da, dc_prev

    def through(da, w):
        """sum_k da_k @ block_k(w): the gradient of the cell's input, w [4H, K]."""
        ks = [k for k in "ifgo" if k in da]
        cat = g.op("Concat", [da[k] for k in ks], axis=1)
        return g.gemm(cat, gates_w(w, ks).T, "bwd", None)

    # head
    dz = mul("vc", mask(f["z"])) if nonnegative else "vc"
    dhr = mul(g.gemm(dz, W["wfc"].T, "bwd_head", None), mask(f["hr"]))
    dh = g.op("Pad", [dhr, g.init("pad_top", np.array([LOOKBACK - 1, 0, 0, 0]), np.int64)])
    # layer 2, last step first
    dl1 = [None] * LOOKBACK
    dc = None
    for s in reversed(range(LOOKBACK)):
        da, dc_prev = cell_back(t[2][s], dh, dc)
        if s == 0:
            dl1[0] = through(da, W["w1"])
            break
        dxs = through(da, W["wr1"])  # [R, 2H] = [d layer1[s]; d prev(h)]
        dl1[s] = g.op("Slice", [dxs, g.init(g.name("s"), [0], np.int64), g.init(g.name("e"), [H], np.int64),
                                      g.init(g.name("a"), [1], np.int64)], base="sl")
        dh = unprev(g.op("Slice", [dxs, g.init(g.name("s"), [H], np.int64), g.init(g.name("e"), [2 * H], np.int64),
                                   g.init(g.name("a"), [1], np.int64)], base="sl"))
        dc = unprev(dc_prev)
    # layer 1, last step first; d pb = sum over rows and steps of the gate gradients
    dpb = {k: None for k in "ifgo"}
    dh_rec, dc, dq = None, None, None
    sched = f["sched"]
    for s in reversed(range(LOOKBACK)):
        da, dc_prev = cell_back(t[1][s], add(dl1[s], dh_rec), dc)
        for k, v in da.items():
            dpb[k] = add(dpb[k], g.op("ReduceSum", [v, axis0], keepdims=1))
        if sched is not None:
            dq = add(dq, through(da, sched["w"]))  # [R, 1]
        if s > 0:
            dh_rec = unprev(through(da, W["r0"]))
            dc = unprev(dc_prev)
    gpb = g.op("Concat", [dpb[k] for k in "ifgo"], axis=1)  # f: from steps 2 and 3
    g.nodes.append(helper.make_node("Identity", [gpb], ["gc"], name="gc"))
    body_out = [helper.make_tensor_value_info("gc", TensorProto.FLOAT, [1, 4 * H])]
    if sched is not None:  # d q / d pb_sched = m: the chunk's [1, K] = dq^T . m
        gq = g.op("MatMul", [g.op("Transpose", [dq]), sched["m"]])
        g.nodes.append(helper.make_node("Identity", [gq], ["gqc"], name="gqc"))
        body_out.append(helper.make_tensor_value_info("gqc", TensorProto.FLOAT, [1, sched["k"]]))
    outer, body_nodes, outer_inits, body_inits = _split_outer(g)
    body_nodes = [n for n in body_nodes if n.name != "out"]  # yc is not a body output here
    body = helper.make_graph(
        body_nodes, "chunk_vjp",
        [helper.make_tensor_value_info("xc", TensorProto.FLOAT, [R, n_hourly]),
         helper.make_tensor_value_info("vc", TensorProto.FLOAT, [chunk, n_out])],
        body_out, initializer=body_inits)
    scan_out = ["gpb_chunks"] + (["gq_chunks"] if sched is not None else [])
    scan = helper.make_node("Scan", ["xw", "v"], scan_out, name="chunks", body=body, num_scan_inputs=2)
    tail = [
        helper.make_node("ReduceSum", ["gpb_chunks", "axes01"], ["gpb_sum"], keepdims=0, name="sum_chunks"),
        helper.make_node("Unsqueeze", ["gpb_sum", "axes0_outer"], ["gpb_row"], name="row"),
        helper.make_node("MatMul", ["gpb_row", "w_pT"], ["g_lin" if sched is not None else "g"], name="to_params"),
    ]
    outer_inits = outer_inits + [
        numpy_helper.from_array(np.array([0, 1], dtype=np.int64), "axes01"),
        numpy_helper.from_array(np.array([0], dtype=np.int64), "axes0_outer"),
        numpy_helper.from_array(np.ascontiguousarray(W["w0"], dtype=np.float32), "w_pT"),
    ]
    if sched is not None:  # g += (sum_chunks gq * width) scattered onto the schedule parameters
        n_params = W["w0"].shape[1]
        E = np.zeros((sched["k"], n_params))
        E[np.arange(sched["k"]), sched["idx"]] = sched["width"]
        tail += [
            helper.make_node("ReduceSum", ["gq_chunks", "axes01"], ["gq_sum"], keepdims=0, name="sum_gq"),
            helper.make_node("Unsqueeze", ["gq_sum", "axes0_outer"], ["gq_row"], name="gq_row"),
            helper.make_node("MatMul", ["gq_row", "sched_scatter"], ["g_sched"], name="sched_to_params"),
            helper.make_node("Add", ["g_lin", "g_sched"], ["g"], name="g"),
        ]
        outer_inits.append(numpy_helper.from_array(E.astype(np.float32), "sched_scatter"))
    graph = helper.make_graph(
        outer + [scan] + tail, "bemcal_surrogate_vjp",
        [helper.make_tensor_value_info("p", TensorProto.FLOAT, [1, n_params]),
         helper.make_tensor_value_info("xw", TensorProto.FLOAT, ["chunks", R, n_hourly]),
         helper.make_tensor_value_info("v", TensorProto.FLOAT, ["chunks", chunk, n_out])],
        [helper.make_tensor_value_info("g", TensorProto.FLOAT, [1, n_params])],
        initializer=outer_inits)
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="bemcal_train")
    m.ir_version = 8
    onnx.checker.check_model(m)
    return m


def chunked_hourly(hourly, chunk=CHUNK):
    """[n_chunks, chunk + 2, n_hourly]: chunk k holds hours k*chunk - 2 .. (k+1)*chunk - 1,
    clamped to [0, n_hours - 1] (the graph's ``xw``)."""
    T = hourly.shape[0]
    n = -(-T // chunk)
    u = np.arange(n)[:, None] * chunk - (LOOKBACK - 1) + np.arange(chunk + LOOKBACK - 1)[None, :]
    return np.ascontiguousarray(hourly[np.clip(u, 0, T - 1)])

"""ONNX export of the surrogate: the plain graph (``x`` -> ``y``) and the structured pair
(``w`` -> ``gw``; ``p``, ``gw`` -> ``y``) used by the Rust hot path."""

import warnings

import numpy as np
import torch

from . import LOOKBACK
from .model import Denormalised, StructuredCore, WeatherProjection

OPSET = 17
PLAIN = "surrogate.onnx"
WEATHER = "surrogate_weather.onnx"
CORE = "surrogate_core.onnx"


def _export(module, args, path, input_names, output_names, dynamic_axes):
    module.eval()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module,
            args,
            path,
            dynamo=False,
            opset_version=OPSET,
            input_names=input_names,
            output_names=output_names,
            dynamic_axes=dynamic_axes,
            do_constant_folding=True,
        )


def export_all(model, n_params, n_hourly, scale, nonnegative, out_dir):
    """Writes the three graphs into ``out_dir``; returns their file names."""
    import os

    model = model.cpu().eval()
    n_features = n_params + n_hourly
    plain = Denormalised(model, scale, nonnegative)
    _export(
        plain,
        (torch.zeros(2, LOOKBACK, n_features),),
        os.path.join(out_dir, PLAIN),
        ["x"],
        ["y"],
        {"x": {0: "batch"}, "y": {0: "batch"}},
    )
    wp = WeatherProjection(model, n_params)
    _export(wp, (torch.zeros(5, n_hourly),), os.path.join(out_dir, WEATHER), ["w"], ["gw"],
            {"w": {0: "hours"}, "gw": {0: "hours"}})
    core = StructuredCore(model, n_params, scale, nonnegative)
    gw = torch.zeros(5, 4 * model.lstm.hidden_size)
    _export(core, (torch.zeros(2, n_params), gw), os.path.join(out_dir, CORE), ["p", "gw"], ["y"],
            {"p": {0: "proposals"}, "gw": {0: "hours"}, "y": {0: "proposals", 1: "hours"}})
    return {"plain": PLAIN, "weather": WEATHER, "core": CORE}


def check_with_onnxruntime(out_dir, x, y_torch, p, w, y_year_torch, threads=1):
    """Runs the exported graphs in onnxruntime (when installed) and returns the largest relative
    differences to torch: plain graph on windows ``x``, structured pair on the year for ``p``."""
    try:
        import onnxruntime as ort
    except ImportError:
        return None
    import os

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    sess = lambda f: ort.InferenceSession(os.path.join(out_dir, f), so, providers=["CPUExecutionProvider"])
    y_plain = sess(PLAIN).run(["y"], {"x": x.astype(np.float32)})[0]
    gw = sess(WEATHER).run(["gw"], {"w": w.astype(np.float32)})[0]
    y_core = sess(CORE).run(["y"], {"p": p.astype(np.float32), "gw": gw})[0]

    def rel(a, b):
        return float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-12))

    return {"plain_vs_torch": rel(y_plain, y_torch), "structured_vs_torch": rel(y_core, y_year_torch)}

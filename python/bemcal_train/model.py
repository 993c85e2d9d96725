"""The LSTM surrogate (reference Fig. 8) and its structured, export-friendly equivalent."""

import torch
from torch import nn

from . import LOOKBACK


class Surrogate(nn.Module):
    """LSTM (lookback 3, ``layers`` x ``hidden``) -> ReLU on the last step -> linear head.

    Input ``x`` [batch, 3, n_features] (normalised), output [batch, n_outputs] in normalised
    units (kWh / scale). Every window starts from a zero state.
    """

    def __init__(self, n_features, n_outputs, hidden=128, layers=2):
        super().__init__()
        self.lstm = nn.LSTM(n_features, hidden, layers, batch_first=True)
        self.head = nn.Linear(hidden, n_outputs)

    def forward(self, x):
        out, _ = self.lstm(x)
        return self.head(torch.relu(out[:, -1, :]))


class Denormalised(nn.Module):
    """The exported plain graph: ``y = max(head, 0) * scale`` in kWh (``clamp`` only when the
    outputs are non-negative meters)."""

    def __init__(self, model, scale, nonnegative):
        super().__init__()
        self.model = model
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))
        self.nonnegative = nonnegative

    def forward(self, x):
        y = self.model(x)
        if self.nonnegative:
            y = torch.relu(y)
        return y * self.scale


def _cell(gates, c, hidden):
    i, f, g, o = gates.split(hidden, dim=-1)  # torch gate order
    i, f, g, o = torch.sigmoid(i), torch.sigmoid(f), torch.tanh(g), torch.sigmoid(o)
    c = i * g if c is None else f * c + i * g
    return o * torch.tanh(c), c


class WeatherProjection(nn.Module):
    """Structured graph, part 1 (run once per weather year): the hourly part of the first
    layer's input projection, ``gw = W_w . w + b_ih + b_hh``; ``w`` [n_hours, n_hourly],
    ``gw`` [n_hours, 4*hidden]."""

    def __init__(self, model, n_params):
        super().__init__()
        lstm = model.lstm
        w_ih = lstm.weight_ih_l0.detach()
        self.register_buffer("w_w", w_ih[:, n_params:].t().contiguous())
        self.register_buffer("b", (lstm.bias_ih_l0 + lstm.bias_hh_l0).detach())

    def forward(self, w):
        return w @ self.w_w + self.b


class StructuredCore(nn.Module):
    """Structured graph, part 2 (the per-proposal hot path): ``p`` [n_proposals, n_params]
    normalised parameters and ``gw`` [n_hours, 4*hidden] -> ``y`` [n_proposals, n_hours, n_outputs]
    kWh for every window of the year.

    Same numbers as ``Denormalised(Surrogate)`` on the windows of the year, with less work:
    the parameter part of the first layer's input projection ``W_p . p`` is computed once per
    proposal instead of once per window and step, and the first step of every window starts from
    the zero state so its recurrent terms ``W_hh . h`` vanish in both layers.
    """

    def __init__(self, model, n_params, scale, nonnegative):
        super().__init__()
        lstm = model.lstm
        self.hidden = lstm.hidden_size
        self.layers = lstm.num_layers
        w_ih0 = lstm.weight_ih_l0.detach()
        self.register_buffer("w_p", w_ih0[:, :n_params].t().contiguous())
        self.register_buffer("w_hh0", lstm.weight_hh_l0.detach().t().contiguous())
        for k in range(1, self.layers):
            self.register_buffer(f"w_ih{k}", getattr(lstm, f"weight_ih_l{k}").detach().t().contiguous())
            self.register_buffer(f"w_hh{k}", getattr(lstm, f"weight_hh_l{k}").detach().t().contiguous())
            b = getattr(lstm, f"bias_ih_l{k}") + getattr(lstm, f"bias_hh_l{k}")
            self.register_buffer(f"b{k}", b.detach())
        self.register_buffer("w_fc", model.head.weight.detach().t().contiguous())
        self.register_buffer("b_fc", model.head.bias.detach())
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))
        self.nonnegative = nonnegative

    def forward(self, p, gw):
        hid = self.hidden
        gp = (p @ self.w_p).unsqueeze(1)  # [P, 1, 4H]
        g = torch.cat([gw[:1]] * (LOOKBACK - 1) + [gw], dim=0)  # [T+2, 4H]
        n = g.shape[0]
        steps = [g[s : n - (LOOKBACK - 1) + s].unsqueeze(0) for s in range(LOOKBACK)]
        # layer 0
        hs = []
        h, c = None, None
        for s in range(LOOKBACK):
            gates = steps[s] + gp
            if h is not None:
                gates = gates + h @ self.w_hh0
            h, c = _cell(gates, c, hid)
            hs.append(h)
        for k in range(1, self.layers):
            w_ih, w_hh, b = getattr(self, f"w_ih{k}"), getattr(self, f"w_hh{k}"), getattr(self, f"b{k}")
            h, c = None, None
            out = []
            for s in range(LOOKBACK):
                gates = hs[s] @ w_ih + b
                if h is not None:
                    gates = gates + h @ w_hh
                h, c = _cell(gates, c, hid)
                out.append(h)
            hs = out
        y = torch.relu(hs[-1]) @ self.w_fc + self.b_fc
        if self.nonnegative:
            y = torch.relu(y)
        return y * self.scale

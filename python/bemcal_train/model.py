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


class ScheduledSurrogate(Surrogate):
    """Today's surrogate with the building's schedule as an hourly input: the building family's
    pretrained network (issue 66, ``pretrain.py``'s conditioned inputs) folded onto one
    building. The schedule's value at hour t is the value of the schedule interval covering t,
    a calibrated parameter for some hours, so it is bilinear in the inputs: the hourly part of
    ``x`` ends with one indicator column per calibrated schedule parameter (``m_k(t)`` = 1
    where parameter ``sched_params[k]`` covers hour t), and the LSTM reads ``x`` and one more
    column, ``q(t) = sum_k m_k(t) * sched_width[k] * p[sched_params[k]]`` (``p`` normalised, so
    ``width * p`` is the value above the prior's minimum; the minimum, the fixed intervals'
    values and the normalisation are affine in the hourly columns and live in the LSTM's
    weights). Input and output as ``Surrogate``'s."""

    def __init__(self, n_features, n_outputs, hidden, layers, sched_params, sched_width):
        nn.Module.__init__(self)
        self.lstm = nn.LSTM(n_features + 1, hidden, layers, batch_first=True)
        self.head = nn.Linear(hidden, n_outputs)
        self.register_buffer("sched_params", torch.as_tensor(list(sched_params), dtype=torch.long))
        self.register_buffer("sched_width", torch.as_tensor(list(sched_width), dtype=torch.float32))

    def schedule_term(self, x):
        """``q`` [batch, 3, 1]."""
        k = self.sched_params.shape[0]
        if k == 0:
            return torch.zeros_like(x[..., :1])
        m = x[..., x.shape[-1] - k:]
        return (m * x[..., self.sched_params] * self.sched_width).sum(-1, keepdim=True)

    def forward(self, x):
        return super().forward(torch.cat([x, self.schedule_term(x)], dim=-1))


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

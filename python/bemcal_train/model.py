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

"""Adam, written out (Kingma & Ba, "Adam: a method for stochastic optimization", ICLR 2015,
Algorithm 1, with the bias corrections folded into the step as in their section 2).

It makes the update `torch.optim.Adam` makes with the defaults the training uses (betas 0.9 and
0.999, eps 1e-8, no weight decay, no amsgrad), in its single-tensor form. It exists because
`torch.optim`'s first optimizer imports `torch._dynamo` (its `add_param_group` is wrapped by
`torch._disable_dynamo`): 9 s of a 28 s training job on a 2-core machine, more than the training
of a small surrogate itself. `python -m bemcal_train.adam` checks it against `torch.optim.Adam`.
"""

import math

import torch


class Adam:
    """Adam over `params` (tensors with `requires_grad`) at learning rate `lr`."""

    def __init__(self, params, lr, betas=(0.9, 0.999), eps=1e-8):
        self.params = [p for p in params if p.requires_grad]
        self.lr, (self.beta1, self.beta2), self.eps = lr, betas, eps
        self.m = [torch.zeros_like(p) for p in self.params]  # first moment
        self.v = [torch.zeros_like(p) for p in self.params]  # second raw moment
        self.t = 0

    def zero_grad(self):
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self):
        self.t += 1
        step_size = self.lr / (1 - self.beta1**self.t)
        root_correction2 = math.sqrt(1 - self.beta2**self.t)
        for p, m, v in zip(self.params, self.m, self.v):
            if p.grad is None:
                continue
            g = p.grad
            m.lerp_(g, 1 - self.beta1)
            v.mul_(self.beta2).addcmul_(g, g, value=1 - self.beta2)
            denom = (v.sqrt() / root_correction2).add_(self.eps)
            p.addcdiv_(m, denom, value=-step_size)


def _check():
    """Trains the same small LSTM for 50 steps with this Adam and torch's; prints and returns the
    largest relative difference of the weights (float32 rounding: about 1e-6)."""
    import sys

    torch.set_num_threads(1)

    def run(make):
        torch.manual_seed(0)
        net = torch.nn.LSTM(5, 16, num_layers=2, batch_first=True)
        head = torch.nn.Linear(16, 3)
        params = list(net.parameters()) + list(head.parameters())
        opt = make(params)
        gen = torch.Generator().manual_seed(1)
        for _ in range(50):
            x = torch.randn(8, 12, 5, generator=gen)
            y = torch.randn(8, 3, generator=gen)
            loss = torch.mean((head(net(x)[0][:, -1]) - y) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
        return params

    ours = run(lambda ps: Adam(ps, lr=1e-3))
    dynamo_before = "torch._dynamo" in sys.modules
    theirs = run(lambda ps: torch.optim.Adam(ps, lr=1e-3, foreach=False))
    with torch.no_grad():
        diff = max(float((a - b).abs().max() / b.abs().max().clamp_min(1e-12)) for a, b in zip(ours, theirs))
    print(f"Adam vs torch.optim.Adam after 50 steps: max relative weight difference {diff:.2e}; "
          f"torch._dynamo imported by ours: {dynamo_before}")
    return diff, dynamo_before


if __name__ == "__main__":
    d, imported = _check()
    raise SystemExit(0 if d < 1e-5 and not imported else 1)

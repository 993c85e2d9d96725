#!/usr/bin/env python3
"""Generate the ArviZ ground truth for bemcal-stats' convergence diagnostics.

Writes crates/stats/tests/fixtures/arviz_reference.json: several draw sets
(chains x draws, fixed numpy seed) with ArviZ's rank-normalised split R-hat
(`az.rhat(method="rank")`), bulk and tail ESS (`az.ess(method="bulk"|"tail")`)
and numpy's mean, sd (ddof=1, as `az.summary`) and linear-interpolation
quantiles (q5, q50, q95) over all draws.

Run it from a throwaway environment outside the repository, e.g.

    python3 -m venv /tmp/arviz-venv
    /tmp/arviz-venv/bin/pip install arviz numpy
    /tmp/arviz-venv/bin/python python/tools/diagnostics_reference.py
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import arviz as az
import numpy as np

SEED = 20240601
OUT = Path(__file__).resolve().parents[2] / "crates/stats/tests/fixtures/arviz_reference.json"


def ar1(rng: np.random.Generator, chains: int, draws: int, rho: float) -> np.ndarray:
    x = np.empty((chains, draws))
    x[:, 0] = rng.normal(size=chains) / math.sqrt(1.0 - rho * rho)
    for t in range(1, draws):
        x[:, t] = rho * x[:, t - 1] + rng.normal(size=chains)
    return x


def draw_sets(rng: np.random.Generator) -> dict[str, np.ndarray]:
    sets = {}
    sets["gaussian_4x500"] = rng.normal(loc=2.0, scale=0.5, size=(4, 500))
    sets["ar1_rho0.9_odd_4x301"] = ar1(rng, 4, 301, 0.9)
    shifted = rng.normal(size=(4, 400))
    shifted += np.array([0.0, 0.0, 1.0, 1.5])[:, None]
    sets["shifted_chains_4x400"] = shifted
    sets["heavy_tail_t2_4x250"] = rng.standard_t(df=2.0, size=(4, 250))
    sets["single_chain_odd_1x201"] = ar1(rng, 1, 201, 0.5)
    # Many ties: exercises average ranks in the rank normalisation.
    sets["discrete_ties_3x120"] = rng.poisson(lam=3.0, size=(3, 120)).astype(float)
    return sets


def finite_or_none(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def main() -> int:
    rng = np.random.default_rng(SEED)
    out = {
        "generator": "python/tools/diagnostics_reference.py",
        "arviz_version": az.__version__,
        "numpy_version": np.__version__,
        "seed": SEED,
        "notes": (
            "rhat = az.rhat(method='rank') (max of bulk and tail), ess_bulk = az.ess(method='bulk'), "
            "ess_tail = az.ess(method='tail'), sd uses ddof=1, quantiles are numpy's default "
            "linear interpolation over all draws. null = NaN (R-hat needs >= 2 chains)."
        ),
        "sets": [],
    }
    for name, draws in draw_sets(rng).items():
        ds = az.convert_to_dataset({"x": draws})  # dims (chain, draw)
        rhat = az.rhat(ds, method="rank")["x"].item()
        ess_bulk = az.ess(ds, method="bulk")["x"].item()
        ess_tail = az.ess(ds, method="tail")["x"].item()
        flat = draws.ravel()
        q5, q50, q95 = np.quantile(flat, [0.05, 0.5, 0.95])
        out["sets"].append(
            {
                "name": name,
                "chains": int(draws.shape[0]),
                "draws_per_chain": int(draws.shape[1]),
                "draws": [[float(v) for v in chain] for chain in draws],
                "rhat": finite_or_none(rhat),
                "ess_bulk": finite_or_none(ess_bulk),
                "ess_tail": finite_or_none(ess_tail),
                "mean": float(np.mean(flat)),
                "sd": float(np.std(flat, ddof=1)),
                "q5": float(q5),
                "q50": float(q50),
                "q95": float(q95),
            }
        )
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {OUT} ({OUT.stat().st_size} bytes), arviz {az.__version__}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Checks `bemcal.load` on a finished calibration against the files it was read from.

Run by tests/calibrate.rs: python check_load.py OUT_DIR DIAGNOSE.json EXPORT.nc PROJECT.toml,
with the repository's python/ on PYTHONPATH and BEMCAL_BIN set. DIAGNOSE.json is `bemcal
diagnose --draws OUT_DIR/draws.csv --json`, EXPORT.nc is `bemcal export OUT_DIR --to
EXPORT.nc`; PROJECT.toml calibrated OUT_DIR (`bemcal.calibrate` reruns it there: every stage is
reused, so it only streams the binary's lines and loads the folder again).
Exits non-zero (an AssertionError and its message) at the first mismatch.
"""

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

warnings.simplefilter("ignore", FutureWarning)
import arviz as az  # noqa: E402

import bemcal  # noqa: E402

out, diagnose_file, export_file, project = (Path(a) for a in sys.argv[1:5])
result = bemcal.load(out)
data = result.posterior
summary = json.loads((out / "summary.json").read_text())
draws = pd.read_csv(out / "draws.csv")

# Groups and dimensions.
for group in ["posterior", "sample_stats", "prior", "observed_data", "posterior_predictive", "constant_data"]:
    assert group in data.groups(), f"no {group} group: {data.groups()}"
chains = sorted(draws["chain"].unique())
per_chain = draws.groupby("chain").size()
assert per_chain.nunique() == 1, per_chain
assert data.posterior.sizes["chain"] == len(chains), data.posterior.sizes
assert data.posterior.sizes["draw"] == per_chain.iloc[0], data.posterior.sizes
calibrated = [p["name"] for p in summary["posterior"]["parameters"]]
assert list(data.posterior.data_vars) == calibrated, (list(data.posterior.data_vars), calibrated)
assert result.parameters == calibrated

# Values: every draw of every parameter, and the log posterior as sample_stats.lp.
for k, chain in enumerate(chains):
    rows = draws[draws["chain"] == chain].sort_values("draw")
    for name in calibrated:
        got = data.posterior[name].sel(chain=k).to_numpy()
        assert np.array_equal(got, rows[name].to_numpy()), name
    assert np.array_equal(data.sample_stats["lp"].sel(chain=k).to_numpy(), rows["log_posterior"].to_numpy())

# The sampler's statistics per draw (CmdStan's columns), as ArviZ names them.
for column, name in [("accept_stat__", "acceptance_rate"), ("stepsize__", "step_size"),
                     ("n_leapfrog__", "n_steps"), ("divergent__", "diverging")]:
    assert column in draws.columns, f"draws.csv has no {column}: {list(draws.columns)}"
    for k, chain in enumerate(chains):
        rows = draws[draws["chain"] == chain].sort_values("draw")
        got = data.sample_stats[name].sel(chain=k).to_numpy()
        assert np.array_equal(got, rows[column].to_numpy().astype(got.dtype)), name
accept = data.sample_stats["acceptance_rate"].to_numpy()
assert ((0 <= accept) & (accept <= 1)).all()
assert (data.sample_stats["step_size"].to_numpy() > 0).all(), "HMC draws have a step size"
assert (data.sample_stats["n_steps"].to_numpy() >= 1).all()

# Summary statistics: the InferenceData's against summary.json's.
for p in summary["posterior"]["parameters"]:
    x = data.posterior[p["name"]].to_numpy().ravel()
    assert abs(x.mean() - p["mean"]) <= 1e-9 * max(1.0, abs(p["mean"])), p["name"]
    assert abs(np.median(x) - p["median"]) <= 1e-9 * max(1.0, abs(p["median"])), p["name"]
priors = {p["name"]: p for p in summary["parameters"]}
for name in calibrated:
    x = data.prior[name].to_numpy()
    assert priors[name]["prior_min"] <= x.min() and x.max() <= priors[name]["prior_max"], name

# Hourly groups: 8,760 hours; measured meters as in posterior_predictive.csv.
outputs = summary["outputs"]
hours = data.observed_data.sizes["hour"]
assert hours == 8760, hours
pp = pd.read_csv(out / "posterior_predictive.csv")
for o in outputs:
    got = data.observed_data[o].to_numpy()
    want = pp[f"{o}_measured"].to_numpy(dtype=float)
    assert np.array_equal(np.isnan(got), np.isnan(want)), o
    assert np.allclose(got[~np.isnan(got)], want[~np.isnan(want)]), o
    assert data.posterior_predictive[o].sizes["hour"] == hours
assert data.posterior_predictive.sizes["draw"] == summary["predictive"]["draws"] - summary["predictive"]["failed"], (
    data.posterior_predictive.sizes, summary["predictive"])
assert "dry_bulb_c" in data.constant_data, list(data.constant_data.data_vars)

# Tables and the estimate.
estimate = dict(summary["calibrated_values"]) if isinstance(summary["calibrated_values"], list) else summary["calibrated_values"]
assert result.estimate == {k: float(v) for k, v in estimate.items()}
in_sample = result.metrics.query("model == 'calibrated' and period == 'in_sample' and resolution == 'hourly'")
for m in summary["validation"]:
    row = in_sample[in_sample["output"] == m["output"]].iloc[0]
    assert row["nmbe_pct"] == m["nmbe"] and row["cv_rmse_pct"] == m["cv_rmse"], m["output"]
assert len(result.predictions) == 8760
assert result.model_path is not None and result.model_path.name == "calibrated.idf"

# ArviZ's own diagnostics agree with `bemcal diagnose` (rank-normalised split R-hat, bulk and
# tail ESS; Vehtari et al. 2021) to 1e-6.
table = az.summary(data, var_names=calibrated, round_to="none")
diagnose = {d["parameter"]: d for d in json.loads(diagnose_file.read_text())}
worst = 0.0
for name in calibrated:
    d, a = diagnose[name], table.loc[name]
    for ours, theirs in [("rhat", "r_hat"), ("ess_bulk", "ess_bulk"), ("ess_tail", "ess_tail"), ("mean", "mean"), ("sd", "sd")]:
        diff = abs(d[ours] - a[theirs])
        worst = max(worst, diff / max(1.0, abs(a[theirs])))
        assert diff <= 1e-6 * max(1.0, abs(a[theirs])), f"{name} {ours}: bemcal {d[ours]!r} vs ArviZ {a[theirs]!r}"

# `bemcal export` wrote the same InferenceData.
back = az.from_netcdf(export_file)
assert set(back.groups()) == set(data.groups()), (back.groups(), data.groups())
for group in data.groups():
    for name, var in getattr(data, group).data_vars.items():
        theirs = getattr(back, group)[name].to_numpy()
        assert np.array_equal(var.to_numpy(), theirs, equal_nan=var.dtype.kind == "f"), (group, name)
# bemcal.calibrate: the binary's lines stream through `echo` as they come, and the result is
# the folder loaded again (the same draws: every stage was reused).
lines = []
again = bemcal.calibrate(project, out=out, workers=0, echo=lines.append)
assert any("reusing" in l for l in lines), lines[-20:]
assert again.draws.equals(result.draws)
assert again.estimate == result.estimate

# The binary's progress events (`--progress json`) become the lines `--progress text` prints,
# and in a notebook one block of stage bars updated in place: read, not parsed out of text.
from bemcal._progress import ProgressEvents, TextEcho  # noqa: E402

fed = [
    '{"event":"log","message":"coordinator on http://127.0.0.1:1; starting 2 workers","elapsed_s":0.0}',
    '{"event":"run","run":"r1","state":"running","stage":"design","stages":[{"stage":"design",'
    '"state":"running","done":0,"total":1,"running":1,"worker_seconds":0.0}],"elapsed_s":0.1}',
    '{"event":"run","run":"r1","state":"running","stage":"simulate","stages":[{"stage":"design",'
    '"state":"done","done":1,"total":1,"running":0,"worker_seconds":0.0},{"stage":"simulate",'
    '"state":"running","done":4,"total":12,"running":2,"worker_seconds":41.5}],"elapsed_s":0.6}',
    "timings: total 50 s",
    '{"event":"somethingnew","elapsed_s":51.0}',
]
progress = ProgressEvents()
events = [e for line in fed for e in progress.feed(line)]
kept = [t for k, t in events if k == "line"]
assert kept == ["[    0.0 s] coordinator on http://127.0.0.1:1; starting 2 workers",
                "timings: total 50 s", fed[4]], kept
blocks = [t for k, t in events if k == "block"]
assert len(blocks) == 2, blocks
assert blocks[-1] == ("[    0.6 s] simulate (running)\n"
                      "  design    [####################]   1/1   done\n"
                      "  simulate  [######--------------]   4/12  running (2 running)"), blocks[-1]
printed = []
echo = TextEcho(printed.append)
for line in fed:
    echo(line)
assert printed[:2] == [kept[0], "[    0.1 s] design (running)"], printed

print(f"bemcal.load: {len(data.groups())} groups, {len(chains)} chains x {per_chain.iloc[0]} draws, "
      f"{len(calibrated)} parameters; ArviZ summary within {worst:.1e} of bemcal diagnose")

"""Print the whole calibration's wall time by stage from a summary.json (`make bench`)."""
import json
import sys

path = sys.argv[1]
try:
    s = json.load(open(path))
except FileNotFoundError:
    print(f"whole calibration: no {path} yet: run `make demo` (about an hour) or BENCH_DEMO=1 make bench")
    sys.exit(0)
t = s["timings"]
post = s["posterior"]["parameters"]
print("whole calibration, paper-size problem (the demo: 20-zone model, 38 parameters, 2 workers)")
for key, label in [
    ("simulations_s", "design points (EnergyPlus)"),
    ("training_s", "surrogate training (PyTorch)"),
    ("chains_s", "chains (optimisation + MH)"),
    ("refinement_s", "refinement draws (EnergyPlus)"),
    ("summary_s", "summary + predictive bands"),
    ("validation_s", "validation (EnergyPlus x 2)"),
    ("total_s", "total"),
]:
    print(f"  {label:32s} {t.get(key, 0.0):8.0f} s")
print(f"  target: total < 2,700 s (45 min): {'met' if t['total_s'] < 2700 else 'NOT met'}")
print(
    f"  max R-hat {max(p['rhat'] for p in post):.3f}, min bulk ESS {min(p['ess_bulk'] for p in post):.0f}; "
    + ", ".join(
        f"{v['output']} NMBE {v['nmbe']:.1f} % CV-RMSE {v['cv_rmse']:.1f} % {'pass' if v['pass'] else 'FAIL'}"
        for v in s["validation"]
    )
)

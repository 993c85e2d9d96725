"""Experiment (issue 66): does distilling the fine-tuned pretrained network into today's
per-building surrogate beat today's from-scratch surrogate on the same own points?

For each held-out building of the learning curve: the pretrained network of corpus size SIZE
(from scripts/learning_curve.sh's OUT folder) fine-tuned on the building's first OWN points;
V virtual design points (a Latin hypercube over the building's prior ranges) predicted by it;
today's architecture trained from scratch on the V virtual + OWN real points (pretrain.from_scratch,
its settings); all three tested on the building's last 5 points, hourly CV-RMSE per meter.
Writes OUT/distill_<SIZE>_V<V>_own<OWN>.json.

    SIZE=100 V=60 OWN=20 .venv/bin/python scripts/pretrained_distill.py
"""
import copy, json, os, sys, time
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
import numpy as np, torch
from bemcal_train import pretrain as P
from bemcal_train.model import Surrogate

CORPUS = os.environ.get("CORPUS", os.path.expanduser("~/.cache/bemcal/corpus"))
FAM, HO = os.path.join(CORPUS, "family"), os.path.join(CORPUS, "heldout")
CUR = os.environ.get("OUT", os.path.expanduser("~/.cache/bemcal/curve"))
SIZE = os.environ.get("SIZE", "100")
V = int(os.environ.get("V", "60"))
OWN = int(os.environ.get("OWN", "20"))
torch.set_num_threads(1)
args = P.parser().parse_args(["curve", "--corpus", FAM, "--heldout", HO])
res = json.load(open(f"{CUR}/curve.json"))
cardj = res["sizes"][SIZE]["card"]
norm = P.Normaliser(state=cardj["normalisation"])
n_feat = len(cardj["inputs"]["static"]) + 9
model = Surrogate(n_feat, len(cardj["outputs"]), 64, 2)
model.load_state_dict(torch.load(f"{CUR}/pretrained_{SIZE}.pt"))
climates = {}
out = {}
rng = np.random.default_rng(0)
for b, hc in P.heldout_buildings(HO, norm, climates):
    pts = len(hc.rows)
    test = list(range(pts - 5, pts))
    own = list(range(OWN))
    t0 = time.time()
    m, _ = P.finetune(model, hc, norm, own, args)
    ft = time.time() - t0
    r0 = hc.rows[0]
    names = sorted(r0["values"])
    # Latin hypercube over the building's prior ranges
    u = (np.argsort(rng.random((V, len(names))), axis=0) + rng.random((V, len(names)))) / V
    vrows = []
    for i in range(V):
        vals = {n: r0["ranges"][n][0] + u[i, j] * (r0["ranges"][n][1] - r0["ranges"][n][0]) for j, n in enumerate(names)}
        vrows.append(dict(r0, values=vals, key=f"virtual{i}"))
    vc = copy.copy(hc)
    vc.rows = vrows
    vc.static = np.array([P.describe(r["spec"]) + P.engineering(r["values"], r["floor_area_m2"]) for r in vrows])
    off = hc.climates[hc.climate[0]][:, 4] != 0
    vc.sched = np.stack([P.schedule_hours(r["spec"], r["values"], off) for r in vrows])
    vc.climate = [hc.climate[0]] * V
    vc.y = np.zeros((V,) + hc.y.shape[1:], dtype=np.float32)
    win = P.Windows(vc, norm, "cpu")
    t0 = time.time()
    vy = P.predict(m, win, list(range(V))).numpy() * norm.y_scale
    pred_s = time.time() - t0
    mc = copy.copy(hc)
    idx = own + test
    mc.rows = vrows + [hc.rows[i] for i in idx]
    mc.y = np.concatenate([vy.astype(np.float32), hc.y[idx]])
    mc.climate = [hc.climate[0]] * len(mc.rows)
    train = list(range(V + OWN))
    tst = list(range(V + OWN, V + OWN + 5))
    t0 = time.time()
    d = P.from_scratch(mc, train, tst, args, None)
    d["seconds"] = time.time() - t0
    win_h = P.Windows(hc, norm, "cpu")
    f = P.evaluate(m, win_h, hc, test)
    out[b] = {"finetuned": f, "distilled": d, "scratch": res["scratch"].get(str(b)), "finetune_s": ft, "predict_s": pred_s}
    fmt = lambda r: "/".join(f"{r[k]['cv_rmse_pct']:.0f}" for k in P.CALIBRATED_METERS) if r else "-"
    print(f"building {b} {hc.climate[0]}: finetuned{OWN} {fmt(f)}  distilled({OWN}+{V}) {fmt(d)} ({d['seconds']:.0f} s)  scratch20 {fmt(out[b]['scratch'])}", flush=True)
with open(f"{CUR}/distill_{SIZE}_V{V}_own{OWN}.json", "w") as f:
    json.dump(out, f, indent=1)
for how in ("finetuned", "distilled", "scratch"):
    med = np.median([[r[how][m]["cv_rmse_pct"] for m in P.CALIBRATED_METERS] for r in out.values() if r[how]], axis=0)
    print(f"median {how}: " + " / ".join(f"{v:.0f}" for v in med))

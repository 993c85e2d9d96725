"""Command line: python -m bemcal_train --dataset DIR --out DIR [options], or
python -m bemcal_train --add-vjp SURROGATE_DIR (the gradient graph for an older surrogate)."""

import argparse
import sys

from .data import TIME_FEATURES


def parser():
    ap = argparse.ArgumentParser(prog="python -m bemcal_train", description=__doc__)
    ap.add_argument("--dataset", required=True, help="dataset directory (TrainingSet::write)")
    ap.add_argument("--out", required=True, help="output directory for the ONNX graphs and surrogate.json")
    ap.add_argument("--epochs", type=int, default=200)
    ap.add_argument("--patience", type=int, default=20, help="early stopping on the held-out loss")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch-size", type=int, default=1024)
    ap.add_argument("--eval-batch-size", type=int, default=8760)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--lr-schedule", choices=("constant", "cosine"), default="constant",
                    help="cosine: annealed from --lr to 1/100 of it over --epochs")
    ap.add_argument("--hidden", type=int, default=128)
    ap.add_argument("--layers", type=int, default=2)
    ap.add_argument("--time-features", choices=TIME_FEATURES, default="none")
    ap.add_argument("--device", choices=("auto", "cpu", "cuda"), default="cpu")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    ap.add_argument("--init", default=None,
                    help="warm start: a previous surrogate directory whose weights.pt (same parameters, "
                         "outputs and architecture) the training starts from")
    ap.add_argument("--compare-time-features", action="store_true",
                    help="train once per time-feature mode on the same design into OUT/<mode> and "
                         "print the held-out accuracy of each side by side")
    return ap


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--add-vjp"]:
        if len(argv) != 2:
            raise SystemExit("usage: python -m bemcal_train --add-vjp SURROGATE_DIR")
        from .export import add_vjp

        add_vjp(argv[1])
        return 0
    args = parser().parse_args(argv)
    from .train import train

    if not args.compare_time_features:
        train(args)
        return 0
    import copy
    import os

    rows = {}
    for mode in TIME_FEATURES:
        a = copy.copy(args)
        a.time_features = mode
        a.out = os.path.join(args.out, mode.replace("+", "_"))
        print(f"=== time features: {mode} ===", flush=True)
        rows[mode] = train(a)["held_out"]["metrics"]
    print("held-out accuracy by time features (RMSE kWh / CV-RMSE %):")
    names = list(next(iter(rows.values())).keys())
    print("mode".ljust(16) + "".join(n.rjust(28) for n in names))
    for mode, m in rows.items():
        cells = []
        for n in names:
            cv = m[n]["cv_rmse_pct"]
            cells.append(f"{m[n]['rmse_kwh']:.4f} / {'n/a' if cv is None else f'{cv:.2f}'}".rjust(28))
        print(mode.ljust(16) + "".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())

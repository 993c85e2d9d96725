"""``python -m bemcal export OUT --format netcdf --to FILE`` writes a calibration's
InferenceData (what ``bemcal export`` runs); any other arguments go to the ``bemcal`` binary."""

from __future__ import annotations

import argparse
import sys


def export(argv) -> int:
    parser = argparse.ArgumentParser(prog="bemcal export")
    parser.add_argument("out_dir", help="a finished calibration's output folder")
    parser.add_argument("--format", choices=["netcdf"], default="netcdf")
    parser.add_argument("--to", required=True, help="file to write (e.g. posterior.nc)")
    a = parser.parse_args(argv)
    from .results import load

    data = load(a.out_dir).posterior
    data.to_netcdf(a.to, engine="h5netcdf")
    groups = ", ".join(data.groups())
    print(f"{a.to}: InferenceData with groups {groups}")
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["export"]:
        return export(argv[1:])
    from ._binary import run

    return run(argv, ok=range(256))


if __name__ == "__main__":
    sys.exit(main())

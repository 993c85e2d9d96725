"""`make notebook`: executes examples/quick.ipynb in place, so that the notebook in the repository
shows real output (ArviZ's summary and plots, Guideline 14, the calibrated model) of a run of this
revision. The notebook runs in examples/ (its working folder `quick/` is ignored by git); a
finished `examples/quick/calibration` is reused, so delete it for a fresh calibration.

Usage: python scripts/notebook.py [NOTEBOOK]   (BEMCAL_BIN: the binary the module runs)
"""

import sys
import time
from pathlib import Path

import nbclient
import nbformat


def main() -> None:
    path = Path(sys.argv[1] if len(sys.argv) > 1 else "examples/quick.ipynb")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb,
        timeout=7200,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
    )
    t0 = time.time()
    client.execute()
    nbformat.write(nb, path)
    print(f"{path}: executed in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()

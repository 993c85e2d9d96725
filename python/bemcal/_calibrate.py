"""``bemcal.calibrate``: a whole calibration on this machine, from Python."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Callable, Optional, Sequence, Union

from ._binary import run
from ._progress import NotebookEcho, TextEcho, in_notebook
from .results import Calibration, load

#: ``bemcal calibrate``'s status for a calibration that finished without converging (its
#: outputs are kept and loadable; ``summary.json`` says what fell short).
NOT_CONVERGED = 3


def calibrate(
    project: Union[str, Path],
    out: Union[str, Path],
    *,
    workers: int = 2,
    extra_args: Sequence[str] = (),
    echo: Union[Callable[[str], None], str, None] = "auto",
) -> Calibration:
    """Calibrates ``project`` (a project TOML) into the folder ``out`` with a local coordinator
    and ``workers`` worker processes (``bemcal calibrate PROJECT --local-workers N --out OUT``),
    streaming its progress to ``echo``, and returns :func:`load` of the folder.

    The binary reports its progress as events (``--progress json``), which are read, not parsed
    out of text. ``echo`` is called with the lines ``--progress text`` would print;
    ``echo="auto"`` prints them, except in a Jupyter notebook, where the block of stage bars is
    shown once and updated in place (``NotebookEcho``); ``None`` is silent.

    A held-out period is set in the project (``[validation] holdout = "last 3 months"``). A
    calibration that finishes without converging is returned with a warning (its
    ``converged`` is False); any other failure raises :class:`bemcal.BemcalError`. A rerun into
    the same folder reuses every finished stage.
    """
    args = ["calibrate", str(project), "--out", str(out), "--progress", "json"]
    if workers > 0:
        args += ["--local-workers", str(workers)]
    args += list(extra_args)
    if echo == "auto":
        echo = NotebookEcho() if in_notebook() else print
    if echo is not None and not isinstance(echo, NotebookEcho):
        echo = TextEcho(echo)
    try:
        status = run(args, echo=echo, ok=(0, NOT_CONVERGED))
    finally:
        if isinstance(echo, NotebookEcho):
            echo.finish()
    result = load(out)
    if status == NOT_CONVERGED:
        warnings.warn(
            f"the calibration in {out} finished without converging "
            f"(max R-hat {result.summary['convergence'].get('max_rhat')}); "
            "see result.summary['convergence']",
            stacklevel=2,
        )
    return result

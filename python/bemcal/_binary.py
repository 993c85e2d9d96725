"""Finding and running the ``bemcal`` binary."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from collections import deque
from pathlib import Path
from typing import Callable, Iterable, Optional, Sequence

from ._progress import error_tail

#: Variable naming the binary explicitly.
BINARY_VAR = "BEMCAL_BIN"


class BemcalError(RuntimeError):
    """``bemcal`` ended with a failure status; ``status`` is it, ``tail`` its last lines."""

    def __init__(self, args: Sequence[str], status: int, tail: Iterable[str]):
        self.args_run = list(args)
        self.status = status
        self.tail = list(tail)
        super().__init__(
            f"bemcal {' '.join(self.args_run[1:])} exited with status {status}:\n"
            + "\n".join(self.tail)
        )


def binary() -> str:
    """The ``bemcal`` executable: ``$BEMCAL_BIN``, else the one installed in this Python
    environment's scripts folder (where ``pip install bemcal`` puts it), else ``bemcal`` on
    ``PATH``, else a repository build (``target/release/bemcal``) above this file."""
    explicit = os.environ.get(BINARY_VAR)
    if explicit:
        return explicit
    exe = "bemcal.exe" if os.name == "nt" else "bemcal"
    candidates = [Path(sysconfig.get_path("scripts")) / exe, Path(sys.prefix) / "bin" / exe]
    for c in candidates:
        if c.is_file():
            return str(c)
    on_path = shutil.which(exe)
    if on_path:
        return on_path
    for parent in Path(__file__).resolve().parents:
        build = parent / "target" / "release" / exe
        if build.is_file():
            return str(build)
    raise FileNotFoundError(
        "no bemcal binary: install the package (`pip install bemcal`), build the repository "
        f"(`make build`), or set {BINARY_VAR}"
    )


def run(
    args: Sequence[str],
    *,
    echo: Optional[Callable[[str], None]] = print,
    ok: Sequence[int] = (0,),
    tail_lines: int = 40,
) -> int:
    """Runs ``bemcal ARGS``, passing each line it prints (stdout and stderr, in order) to
    ``echo`` as it comes (``None``: silent). Returns the exit status if it is in ``ok``, else
    raises :class:`BemcalError` with the last lines."""
    cmd = [binary(), *map(str, args)]
    tail: deque = deque(maxlen=tail_lines)
    with subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
    ) as proc:
        assert proc.stdout is not None
        try:
            for line in proc.stdout:
                line = line.rstrip("\n")
                tail.extend(error_tail(line))
                if echo is not None:
                    echo(line)
        except BaseException:
            # Interrupted (Ctrl-C, a notebook's stop button) or `echo` failed: the run stops
            # with this call instead of going on unseen (Popen's own exit would leave it
            # running). Its local coordinator and workers end with it; a rerun into the same
            # folder resumes from its finished stages.
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            raise
        status = proc.wait()
    if status not in ok:
        raise BemcalError(cmd, status, tail)
    return status

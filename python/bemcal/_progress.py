"""``bemcal calibrate``'s progress, from its events.

:func:`bemcal.calibrate` runs the binary with ``--progress json``: every progress line on its
standard error is one JSON object (``docs/reference/cli.md``; the binary's ``src/cmd/progress.rs``
documents the events): ``log`` (a line of the calibration's log), ``run`` (a coordinator run's
stages, each time they change) and ``building`` (a portfolio's building changed stage). Any
other line (the results the command prints at the end) is passed on as it is.

:class:`ProgressEvents` turns the lines into what to show: lines to keep and a block of stage
bars that replaces the previous one. :class:`TextEcho` gives a plain callable (``print``) the
lines the binary's ``--progress text`` would have written; :class:`NotebookEcho` shows the block
in one display area, updated in place, with every other line printed as it comes.
"""

from __future__ import annotations

import json
from typing import Callable, List, Optional, Tuple

Event = Tuple[str, str]


def parse_event(line: str) -> Optional[dict]:
    """The progress event a line holds, or None for any other line."""
    if not line.startswith('{"'):
        return None
    try:
        event = json.loads(line)
    except ValueError:
        return None
    return event if isinstance(event, dict) and "event" in event else None


def _stamp(event: dict) -> str:
    return f"[{float(event.get('elapsed_s', 0.0)):>7.1f} s] "


def stage_bar(stage: dict, width: int = 20) -> str:
    """One stage's line, as the binary writes it: ``  simulate  [#####---...]   4/12  running``."""
    done, total = int(stage["done"]), int(stage["total"])
    filled = 0 if total == 0 else done * width // total
    running = f" ({stage['running']} running)" if stage.get("running") else ""
    return (f"  {stage['stage']:<9} [{'#' * filled}{'-' * (width - filled)}] "
            f"{done:>3}/{total:<3} {stage['state']}{running}")


class ProgressEvents:
    """Sorts a command's lines: :meth:`feed` returns ``("block", text)`` to show in place of
    the previous block (a run's stages) and ``("line", text)`` to keep."""

    def feed(self, line: str) -> List[Event]:
        event = parse_event(line)
        if event is None:
            return [("line", line)]
        kind = event["event"]
        if kind == "log":
            return [("line", _stamp(event) + str(event.get("message", "")))]
        if kind == "run":
            head = _stamp(event) + f"{event['stage']} ({event['state']})"
            return [("block", "\n".join([head, *map(stage_bar, event.get("stages", []))]))]
        if kind == "building":
            return [("line", _stamp(event) + f"{event['building']}: {event['progress']}")]
        # An event this version does not know: kept as it came.
        return [("line", line)]


def error_tail(line: str) -> List[str]:
    """What a line leaves in an error's tail (:class:`bemcal.BemcalError`): a log line or a
    building's change as text, any other line as it is; a run's stages (redrawn every change)
    nothing."""
    return [text for kind, text in ProgressEvents().feed(line) if kind == "line"]


class TextEcho:
    """An ``echo`` that passes a plain callable the lines of ``--progress text``."""

    def __init__(self, echo: Callable[[str], None]) -> None:
        self._echo = echo
        self._events = ProgressEvents()

    def __call__(self, line: str) -> None:
        for _, text in self._events.feed(line):
            for part in text.split("\n"):
                self._echo(part)


class NotebookEcho:
    """An ``echo`` for :func:`bemcal.calibrate` in a Jupyter kernel: the progress block in one
    display area, updated in place; every other line printed."""

    def __init__(self) -> None:
        from IPython.display import Pretty, display

        self._pretty, self._display = Pretty, display
        self._events = ProgressEvents()
        self._handle = None

    def __call__(self, line: str) -> None:
        for kind, text in self._events.feed(line):
            if kind == "line":
                print(text)
            elif self._handle is None:
                self._handle = self._display(self._pretty(text), display_id=True)
            else:
                self._handle.update(self._pretty(text))

    def finish(self) -> None:
        """Nothing is held back (each event is shown as it comes); kept for callers."""


def in_notebook() -> bool:
    """True inside a Jupyter (IPython kernel) session."""
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and hasattr(shell, "kernel")

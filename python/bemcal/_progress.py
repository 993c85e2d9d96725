"""``bemcal calibrate``'s progress in a notebook.

The binary redraws a block of stage bars on every change: a ``[  t s] stage (state)`` line,
then one indented line per stage. A terminal shows each block under the last; a notebook cell
would keep every one (hundreds of lines for one calibration). :class:`ProgressLines` sorts the
lines into the current block and the lines to keep, and :class:`NotebookEcho` shows the block in
one display area, updated in place, with every other line printed as it comes.
"""

from __future__ import annotations

import re
from typing import List, Optional, Tuple

_STAMPED = re.compile(r"^\[\s*[0-9.]+ s\] ")
# A stage's bar: `  simulate  [#####---------------]   4/12  running (2 running)`.
_BAR = re.compile(r"^  \S+\s+\[[#-]+\]")

Event = Tuple[str, str]


class ProgressLines:
    """Sorts ``bemcal calibrate``'s lines: :meth:`feed` returns events, ``("block", text)`` to
    show in place of the previous block, ``("line", text)`` to keep."""

    def __init__(self) -> None:
        self._header: Optional[str] = None
        self._bars: List[str] = []

    def feed(self, line: str) -> List[Event]:
        if self._header is not None and _BAR.match(line):
            self._bars.append(line)
            return [("block", "\n".join([self._header, *self._bars]))]
        events = self.finish()
        if _STAMPED.match(line):
            # A block's first line, or a stamped log line: the next line tells.
            self._header = line
        else:
            events.append(("line", line))
        return events

    def finish(self) -> List[Event]:
        """The events still held back: a stamped line that no bars followed."""
        header, bars = self._header, self._bars
        self._header, self._bars = None, []
        return [("line", header)] if header is not None and not bars else []


class NotebookEcho:
    """An ``echo`` for :func:`bemcal.calibrate` in a Jupyter kernel: the progress block in one
    display area, updated in place; every other line printed."""

    def __init__(self) -> None:
        from IPython.display import Pretty, display

        self._pretty, self._display = Pretty, display
        self._lines = ProgressLines()
        self._handle = None

    def __call__(self, line: str) -> None:
        self._show(self._lines.feed(line))

    def finish(self) -> None:
        """Prints what is still held back (call once the binary has exited)."""
        self._show(self._lines.finish())

    def _show(self, events: List[Event]) -> None:
        for kind, text in events:
            if kind == "line":
                print(text)
            elif self._handle is None:
                self._handle = self._display(self._pretty(text), display_id=True)
            else:
                self._handle.update(self._pretty(text))


def in_notebook() -> bool:
    """True inside a Jupyter (IPython kernel) session."""
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and hasattr(shell, "kernel")

"""Progress of long commands, for the CLI and the Python API (``mitsuba_lab.sweep``).

Where someone watches, the bar is tqdm's (``tqdm.auto``): a live bar on a terminal, a widget
in a Jupyter notebook (when ipywidgets is installed), with messages printed above it. Where
the output is a log (a pipe, a CI job, pytest's capture, a notebook without ipywidgets) each
step and each message is one plain line, in tqdm's format but without carriage returns, so
a log never fills with redrawn bars.
"""
from __future__ import annotations

import sys
import time


def duration(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m" if seconds >= 3600 else \
        f"{seconds // 60}m{seconds % 60:02d}s"


def in_notebook() -> bool:
    """True in a Jupyter kernel where tqdm can show its widget (tqdm.auto's own choice)."""
    if "ipykernel" not in sys.modules and "IPython.utils._process_emscripten" not in sys.modules:
        return False                      # the common case, without importing tqdm's notebook part
    from tqdm.auto import tqdm as auto
    from tqdm.notebook import tqdm as widget

    return issubclass(auto, widget)


def is_live(stream) -> bool:
    """Redraw a bar in place on ``stream``: a terminal, or a notebook's cell output."""
    try:
        tty = stream.isatty()
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        tty = False
    return tty or in_notebook()


class ProgressBar:
    """``begin(total)``, then ``step(label)`` per finished item; ``message(text)`` at any time.

    ``live`` (default: ``is_live(stream)``) chooses tqdm's redrawn bar over plain lines.
    """

    def __init__(self, stream=None, live: bool | None = None):
        self.stream = stream or sys.stderr
        self.live = is_live(self.stream) if live is None else live
        self.total = self.done = 0
        self.unit = "it"
        self.start = time.perf_counter()
        self._bar = None

    def begin(self, total: int, label: str = "", unit: str = "it") -> None:
        self.close()
        self.total, self.done, self.unit, self.start = total, 0, unit, time.perf_counter()
        if label:
            self.message(label)
        if self.live and total > 0:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=total, unit=unit, file=self.stream, dynamic_ncols=True, leave=True)

    def step(self, label: str = "") -> None:
        self.done += 1
        if self._bar is not None:
            self._bar.set_postfix_str(label, refresh=False)
            self._bar.update(1)
            if self.done >= self.total:
                self.close()
            return
        from tqdm.std import tqdm

        line = tqdm.format_meter(self.done, self.total, time.perf_counter() - self.start, ascii=True,
                                 unit=self.unit, postfix=label or None)
        self._write(line)

    def message(self, text: str) -> None:
        if self._bar is not None:
            self._bar.write(text, file=self.stream)        # above the bar, which is then redrawn
        else:
            self._write(text)

    def close(self) -> None:
        """End the current bar (left on screen); safe to call twice."""
        bar, self._bar = self._bar, None
        if bar is not None:
            bar.close()

    def _write(self, line: str) -> None:
        self.stream.write(line + "\n")
        self.stream.flush()


class NoProgress(ProgressBar):
    """A ProgressBar that shows nothing (``mitsuba_lab.sweep(..., progress=False)``)."""

    def __init__(self):
        super().__init__(stream=sys.stderr, live=False)

    def begin(self, total: int, label: str = "", unit: str = "it") -> None:
        self.total, self.done = total, 0

    def step(self, label: str = "") -> None:
        self.done += 1

    def message(self, text: str) -> None:
        pass

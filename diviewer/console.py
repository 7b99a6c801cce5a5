"""Progress of long jobs (capture, training): tqdm's bar on a terminal, plain lines in a log file.

In a log (stderr not a terminal, as under ``nohup``) no tqdm bar is drawn at all: tqdm moves the cursor between
nested bars (``ESC[A``), which a log keeps as garbage. A `LogProgress` writes one whole line at most every
`LOG_INTERVAL` seconds instead: the stage, done/total, the rate, the time left, and, inside a `diviewer build`,
the build's overall percentage (`overall`), the stages already finished included.
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

from tqdm import tqdm

LOG_INTERVAL = 30.0
"""Seconds between two progress lines in a log (a last line is written when the job ends)."""

_OVERALL: dict | None = None
"""The build under way (`overall`): its total estimated seconds, those of the stages finished, and the stage's."""


@contextmanager
def overall(total: float, done: float, stage: float):
    """Within the block, every progress line in a log also gives the build's overall percentage: ``done`` seconds
    of ``total`` finished before this stage (of ``stage`` estimated seconds), plus the stage's own fraction."""
    global _OVERALL
    before, _OVERALL = _OVERALL, {"total": max(total, 1e-9), "done": done, "stage": stage}
    try:
        yield
    finally:
        _OVERALL = before


def overall_fraction(stage_fraction: float = 0.0) -> float | None:
    """The build's overall fraction done with the current stage ``stage_fraction`` done; None outside a build."""
    if _OVERALL is None:
        return None
    return min(1.0, (_OVERALL["done"] + _OVERALL["stage"] * stage_fraction) / _OVERALL["total"])


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60:02d}:{rest % 60:02d}"


class LogProgress:
    """tqdm's interface (update, set_postfix_str, close, n, total) as plain lines for a log: no carriage return, no
    escape code. ``initial``: units already done before (a resumed job), counted in the percentage, not the rate."""

    def __init__(self, total: int, desc: str, unit: str, stream, initial: int = 0):
        self.total, self.desc, self.unit, self.stream = total, desc, unit, stream
        self.n = self.initial = initial
        self.postfix = ""
        self.start = self.last = time.monotonic()
        self.closed = False
        self.line(force=True)

    def set_postfix_str(self, s: str, refresh: bool = True) -> None:
        self.postfix = s
        if refresh:
            self.line()

    def update(self, n: int = 1) -> None:
        self.n += n
        self.line()

    def line(self, force: bool = False) -> None:
        """Write the progress line, at most once every `LOG_INTERVAL` seconds unless ``force``."""
        now = time.monotonic()
        if not force and now - self.last < LOG_INTERVAL:
            return
        self.last = now
        self.stream.write(self.text(now) + "\n")
        self.stream.flush()

    def text(self, now: float | None = None) -> str:
        now = time.monotonic() if now is None else now
        elapsed = now - self.start
        done = self.n - self.initial
        frac = self.n / self.total if self.total else 1.0
        parts = [f"{self.desc}: {frac:.0%} {self.n}/{self.total} {self.unit}s"]
        if done > 0 and elapsed > 0:
            rate = done / elapsed
            speed = f"{rate:.2f} {self.unit}s/s" if rate >= 1 else f"{1 / rate:.1f} s a {self.unit}"
            parts.append(f"{speed}, {_duration(elapsed)} elapsed, ~{_duration(max(0, self.total - self.n) / rate)} "
                         f"left")
        elif self.initial:
            parts.append(f"resumed at {self.initial}")
        if self.postfix:
            parts.append(self.postfix)
        build = overall_fraction(frac)
        if build is not None:
            parts.append(f"build {build:.0%} overall")
        return " | ".join(parts)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self.line(force=True)


def progress_bar(total: int, desc: str, unit: str, stream=None, initial: int = 0):
    """Progress of ``total`` units (``initial`` of them done before: a resumed job starts there) on ``stream``
    (stderr by default): tqdm's bar on a terminal, redrawn at most once a second; otherwise a `LogProgress`."""
    stream = stream if stream is not None else sys.stderr
    tty = hasattr(stream, "isatty") and stream.isatty()
    if tty:
        return tqdm(total=total, desc=desc, unit=unit, file=stream, mininterval=1.0, dynamic_ncols=True,
                    initial=initial)
    return LogProgress(total, desc, unit, stream, initial=initial)

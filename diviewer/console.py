"""Progress of long jobs (capture, training): tqdm's bar on a terminal, plain lines in a log file."""

from __future__ import annotations

import sys

from tqdm import tqdm


class _Lines:
    """The stream tqdm writes to when stderr is not a terminal: each refresh becomes one whole line.

    tqdm redraws in place ('\\r' + bar); in a log that is one endless line, so the carriage return
    is dropped and a newline ends each refresh instead.
    """

    def __init__(self, stream):
        self.stream = stream

    def write(self, s: str) -> None:
        s = s.replace("\r", "").rstrip()
        if s:
            self.stream.write(s + "\n")

    def flush(self) -> None:
        self.stream.flush()


def progress_bar(total: int, desc: str, unit: str, stream=None) -> tqdm:
    """A tqdm bar (done/total, rate, elapsed, time left) on ``stream`` (stderr by default).

    On a terminal it redraws at most once a second; otherwise it writes an ASCII line at most every
    30 s (and a last one when closed), so logs of hours-long runs stay readable.
    """
    stream = stream if stream is not None else sys.stderr
    tty = hasattr(stream, "isatty") and stream.isatty()
    if tty:
        return tqdm(total=total, desc=desc, unit=unit, file=stream, mininterval=1.0, dynamic_ncols=True)
    return tqdm(total=total, desc=desc, unit=unit, file=_Lines(stream), mininterval=30.0, ncols=100, ascii=True)

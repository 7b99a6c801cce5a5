"""Progress of long jobs: tqdm's bar; in a log (not a terminal) whole lines without carriage returns."""

from __future__ import annotations

import io
import re

from diviewer.console import progress_bar


def test_progress_in_a_log_is_whole_lines_with_rate_and_time_left():
    log = io.StringIO()  # not a terminal
    bar = progress_bar(4, "capture", "frame", stream=log)
    for _ in range(4):
        bar.set_postfix_str("gt 1.0s/frame", refresh=False)
        bar.update()
    bar.close()
    text = log.getvalue()
    assert "\r" not in text and text.endswith("\n")
    last = text.splitlines()[-1]
    assert last.startswith("capture: 100%") and "4/4" in last and "gt 1.0s/frame" in last
    assert re.search(r"\d\d:\d\d<\d\d:\d\d, [\d.]+frame/s", last), last  # elapsed < left, rate


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_redraws_in_place():
    term = _Terminal()
    bar = progress_bar(2, "train", "step", stream=term)
    bar.update(2)
    bar.close()
    assert "\r" in term.getvalue() and "2/2" in term.getvalue()

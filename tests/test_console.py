"""Progress of long jobs: tqdm's bar; in a log (not a terminal) whole lines without carriage returns."""

from __future__ import annotations

import io
import re

import pytest

from diviewer.console import progress_bar


def test_progress_in_a_log_is_whole_lines_with_rate_and_time_left():
    log = io.StringIO()  # not a terminal
    bar = progress_bar(4, "capture", "frame", stream=log)
    for _ in range(4):
        bar.set_postfix_str("path tracing 1.0 s a frame", refresh=False)
        bar.update()
    bar.close()
    text = log.getvalue()
    assert "\r" not in text and "\x1b[" not in text and text.endswith("\n")
    last = text.splitlines()[-1]
    assert last.startswith("capture: 100% 4/4 frames") and "path tracing 1.0 s a frame" in last
    assert re.search(r"\d\d:\d\d elapsed, ~\d\d:\d\d left", last), last


def test_nested_progress_in_a_log_moves_no_cursor_and_gives_the_builds_overall_share(monkeypatch):
    """A build's stage bar inside the build: plain lines (no ESC[A of tqdm's nested bars), at the interval, each
    with the build's overall percentage counting the stages finished before."""
    import diviewer.console as console

    log = io.StringIO()
    clock = iter(range(0, 10_000, 20))
    monkeypatch.setattr(console.time, "monotonic", lambda: float(next(clock)))
    with console.overall(total=100.0, done=50.0, stage=40.0):
        outer = progress_bar(10, "build", "s", stream=log)
        bar = progress_bar(10, "capture", "frame", stream=log)
        for _ in range(10):
            bar.update()
        bar.close()
        outer.close()
    text = log.getvalue()
    assert "\x1b[" not in text and "\r" not in text
    lines = [line for line in text.splitlines() if line.startswith("capture")]
    assert len(lines) >= 5, text  # lines during the stage (every other update at 20 s a tick and 30 s apart)
    assert "build 50% overall" in lines[0] and lines[-1].endswith("build 90% overall")
    assert all(re.search(r"\d+%", line) for line in lines)


def test_a_resumed_progress_starts_at_the_units_done():
    log = io.StringIO()
    bar = progress_bar(10, "capture", "frame", stream=log, initial=6)
    assert bar.n == 6
    assert log.getvalue().splitlines()[0].startswith("capture: 60% 6/10 frames")
    bar.update(4)
    bar.close()
    assert "100% 10/10" in log.getvalue().splitlines()[-1]
    term = _Terminal()
    tbar = progress_bar(10, "train", "step", stream=term, initial=6)
    tbar.close()
    assert tbar.n == 6 and "6/10" in term.getvalue()


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_on_a_terminal_redraws_in_place():
    term = _Terminal()
    bar = progress_bar(2, "train", "step", stream=term)
    bar.update(2)
    bar.close()
    assert "\r" in term.getvalue() and "2/2" in term.getvalue()


@pytest.mark.mitsuba
@pytest.mark.gl
def test_a_resumed_capture_in_a_log_starts_at_the_frames_done_and_says_what_its_figures_are(gl_context, tmp_path,
                                                                                             capsys):
    from diviewer.data.capture import CaptureSettings, capture

    tiny = dict(width=32, height=32, spp=2, max_depth=3, thumbs=0)
    out = tmp_path / "cap"
    capture("cornell", out, CaptureSettings(frames=3, seed=1, **tiny), log=lambda *_: None)
    (out / "frames" / "000002.npy").unlink()  # one frame lost: the resumed capture renders it alone
    capsys.readouterr()
    capture("cornell", out, CaptureSettings(frames=3, seed=1, **tiny), log=lambda *_: None)
    err = capsys.readouterr().err  # not a terminal
    assert "\x1b[" not in err and "\r" not in err
    lines = [line for line in err.splitlines() if line.startswith("capture:")]
    assert lines[0].startswith("capture: 67% 2/3 frames"), err
    assert lines[-1].startswith("capture: 100% 3/3 frames") and re.search(r"path tracing [\d.]+ s a frame", lines[-1])

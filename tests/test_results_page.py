"""docs/results.md and README.md's headline table are what tools/make_results.py writes from the shipped data:
the page is regenerated in memory and compared byte for byte, so a card, a ladder record or a measurement that
changes without the page (or a hand edit of the page) fails here."""

from __future__ import annotations

import json
import shutil

from tool_modules import load_tool

make_results = load_tool("make_results")


def test_the_page_and_the_readme_are_what_the_data_gives():
    for rel, text in make_results.build().items():
        on_disk = (make_results.ROOT / rel).read_text(encoding="utf-8")
        assert on_disk == text, f"{rel} differs from the data: run python tools/make_results.py"


def test_every_file_the_page_reads_is_tracked_data():
    for scene, src in make_results.SOURCES.items():
        for rel in (src["eval"], src["bench"], f"assets/models/{scene}.json"):
            assert (make_results.ROOT / rel).is_file(), rel
        card = json.loads((make_results.ROOT / f"assets/models/{scene}.json").read_text())
        assert (make_results.ROOT / "assets/models" / card["ladder"]["file"]).is_file()


def test_a_changed_figure_changes_the_page(tmp_path, monkeypatch):
    """A score moved in a card's evaluation reaches the page and the README, and --check then reports it."""
    root = tmp_path / "tree"
    for rel in ["README.md", "docs/results.md", "assets/models", *(
            p for s in make_results.SOURCES.values() for p in (s["eval"], s["bench"], s["shown"][0]))]:
        src, dst = make_results.ROOT / rel, root / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        (shutil.copytree if src.is_dir() else shutil.copy)(src, dst)
    monkeypatch.setattr(make_results, "ROOT", root)
    assert make_results.main(["--check"]) == 0
    rel = make_results.SOURCES["cornell"]["eval"]
    data = json.loads((root / rel).read_text())
    score = data["splits"]["unseen_configs"]["methods"]["cornell_k16"]["psnr_tm"]
    score["mean"] = 12.345
    (root / rel).write_text(json.dumps(data))
    assert make_results.main(["--check"]) == 1
    assert make_results.main([]) == 0
    assert "**12.35**" in (root / "docs/results.md").read_text() and "**12.3 dB**" in (root / "README.md").read_text()
    assert make_results.main(["--check"]) == 0

"""tools/relayout_json.py: JSON files laid out by rows, read back the same, refused when they are not strict JSON."""

from __future__ import annotations

import json

import pytest

from tool_modules import load_tool

RECORD = {"evalset": "runs/x", "splits": {"s": {"frames": [{"i": i, "psnr": 30.0 + i / 7} for i in range(5)]}},
          "b_key": [0.1, 0.2], "a_key": None}


def test_files_are_laid_out_by_rows_with_their_content_and_key_order_kept(tmp_path, capsys):
    tool = load_tool("relayout_json")
    (tmp_path / "d").mkdir()
    wide = tmp_path / "d" / "eval.json"
    wide.write_text(json.dumps(RECORD, indent=1) + "\n")
    assert tool.main(["--check", str(tmp_path)]) == 1 and "eval.json: not laid out by rows" in capsys.readouterr().out
    assert tool.main([str(tmp_path)]) == 0
    assert "1 of 1 JSON files laid out by rows" in capsys.readouterr().out
    text = wide.read_text()
    assert json.loads(text) == RECORD and list(json.loads(text)) == list(RECORD) and text.endswith("}\n")
    assert len(text) < len(json.dumps(RECORD, indent=1)) and '    {"i": 0, "psnr": 30.0},' in text.splitlines()
    assert tool.main(["--check", str(wide)]) == 0  # idempotent
    assert tool.main([str(wide)]) == 0 and wide.read_text() == text


@pytest.mark.parametrize("text, needle", [('{"psnr": NaN}', "NaN is not strict JSON"),
                                          ('{"a": ', "cannot be laid out")])
def test_a_file_that_is_not_strict_json_is_refused_by_name_and_left_as_it_is(tmp_path, capsys, text, needle):
    tool = load_tool("relayout_json")
    good, bad = tmp_path / "a.json", tmp_path / "b.json"
    good.write_text(json.dumps(RECORD, indent=1))
    bad.write_text(text)
    assert tool.main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and needle in err
    assert bad.read_text() == text and good.read_text() == json.dumps(RECORD, indent=1)  # nothing written


def test_a_missing_target_is_named(tmp_path, capsys):
    assert load_tool("relayout_json").main([str(tmp_path / "nowhere")]) == 2
    assert "nowhere: no such file or folder" in capsys.readouterr().err

"""What a settings field accepts: a bool is not a number, 12.7 not a whole number, NaN nowhere, names by list."""

from __future__ import annotations

import math

import pytest

from diviewer.errors import DiviewerError
from diviewer.fieldspec import (Bool, Choice, Float, Floats, Int, Ints, Invalid, Maybe, Table, Text, check_fields,
                                check_value)


@pytest.mark.parametrize("spec,good,bad", [
    (Int(1, 10), [1, 10], [0, 11, True, False, 12.7, 3.0, "3", None, math.nan]),
    (Int(16, 256, power_of_two=True), [16, 64, 256], [8, 48, 512]),
    (Float(0.0, 1.0, hi_open=True), [0, 0.0, 0.5], [1.0, -1e-9, math.nan, math.inf, True, "0.5"]),
    (Float(0.0, 1.0, lo_open=True), [1e-300, 1], [0, 0.0, -math.inf]),
    (Bool(), [True, False], [0, 1, "no", "true", None]),
    (Choice(("NHWC", "NCHW")), ["NHWC"], ["NCWH", "nhwc", 0, True]),
    (Text(5), ["", "abcde"], ["abcdef", 5, ["a"], True]),
    (Ints(Int(1, 100), increasing=True), [[1], (1, 2, 50)], [[], [2, 1], [1, 1], [1, True], [1, 2.5], 4, "1,2"]),
    (Ints(Int(1, 100), min_len=0, distinct=True), [[], [3, 1]], [[1, 1]]),
    (Floats(3, Float(0.0, 1.0)), [[0.8, 0.1, 0.1], (1, 0, 0)], [[0.5, 0.5], [0.5, 0.5, math.nan], "0.8"]),
    (Maybe(Int(1, 5)), [None, 3], [0, 6, True]),
    (Table({"levels": Int(1, 5)}), [{}, {"levels": 2}], [{"levels": 0}, {"other": 1}, 3, [1]]),
])
def test_each_spec_takes_its_values_and_refuses_the_rest(spec, good, bad):
    for v in good:
        spec.check(v)
    for v in bad:
        with pytest.raises(Invalid):
            spec.check(v)


def test_checked_values_are_as_the_settings_hold_them():
    assert Float(0, 10).check(3) == 3.0 and isinstance(Float(0, 10).check(3), float)
    assert Ints(Int(1, 9)).check([1, 2]) == (1, 2) and Floats(2, Float(0, 9)).check([1, 2]) == (1.0, 2.0)


def test_refusals_name_the_file_and_the_table_field():
    with pytest.raises(DiviewerError, match=r"^r\.toml: capture\.frames: must be a whole number from 1 to 9, got 12\.7"):
        check_fields({"frames": 12.7}, {"frames": Int(1, 9)}, "capture", "r.toml")
    with pytest.raises(DiviewerError, match=r"capture\.fps: unknown key 'fps'; \[capture\] takes frames"):
        check_fields({"fps": 4}, {"frames": Int(1, 9)}, "capture", "r.toml")
    with pytest.raises(DiviewerError, match=r"capture\.truth_filter\.levels: must be .*, got 0$"):
        check_value(Table({"levels": Int(1, 5)}), {"levels": 0}, "capture.truth_filter", "r.toml")

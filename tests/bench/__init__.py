"""Tests of diviewer/bench/, one file per module (test_<module>.py)."""

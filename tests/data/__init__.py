"""Tests of diviewer/data/, one file per module (test_<module>.py)."""

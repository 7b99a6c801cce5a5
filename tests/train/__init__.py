"""Tests of diviewer/train/, one file per module (test_<module>.py)."""

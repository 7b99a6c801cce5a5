"""Tests of diviewer/viewer/, one file per module (test_<module>.py)."""

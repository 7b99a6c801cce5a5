"""Tests of diviewer/reference/, one file per module (test_<module>.py)."""

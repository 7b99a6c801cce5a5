"""Tests of diviewer/gl/, one file per module (test_<module>.py)."""

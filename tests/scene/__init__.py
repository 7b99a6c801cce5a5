"""Tests of diviewer/scene/, one file per module (test_<module>.py)."""

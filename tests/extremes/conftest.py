"""The extremes suite: every test here carries the `extremes` marker; hypothesis runs few, fixed examples."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, settings

# Few examples, derandomised: the suite runs in minutes on 2 cores and gives the same cases in CI.
settings.register_profile("extremes", max_examples=12, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.load_profile("extremes")


def pytest_collection_modifyitems(items):
    for item in items:
        if "tests/extremes/" in str(item.fspath).replace("\\", "/"):
            item.add_marker(pytest.mark.extremes)

"""Shared helpers for the suites (fixtures come from the ckesc pytest plugin)."""

import pytest


# every conformance test gets a timeout: a silent DUT must fail fast, never hang the run
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("timeout") is None:
            item.add_marker(pytest.mark.timeout(120))

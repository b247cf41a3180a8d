"""Shared helpers for the suites (fixtures come from the ckesc pytest plugin)."""

import pytest

# The helper modules beside the suites hold what several section modules share (README.md): their
# asserts fail tests as the test modules' do, with pytest's explanation in the message. Registered
# here, before any test module imports them.
pytest.register_assert_rewrite("conformance.reports", "conformance.answers", "conformance.multi_esc", "conformance.motor",
                              "conformance.codes", "conformance.wire", "conformance.physics",
                              "conformance.raw_command_12b")


# every conformance test gets a timeout: a silent DUT must fail fast, never hang the run
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("timeout") is None:
            item.add_marker(pytest.mark.timeout(120))

"""pytest hooks for the suites (fixtures come from the ckesc pytest plugin, shared helpers from the
non-test modules beside this one: README.md)."""

import pytest

# The helper modules beside the suites hold what several section modules share (README.md): their
# asserts fail tests as the test modules' do, with pytest's explanation in the message, as when the
# code stood in test modules. Registered here, before any test module imports them. (throttle.py,
# a helper module from the start, never was: its messages stay as they were.)
pytest.register_assert_rewrite(*(f"conformance.{m}" for m in (
    "answers", "baud", "codes", "motor", "multi_esc", "physics", "raw_command_12b", "settings", "showing", "telemetry", "wire")))


# every conformance test gets a timeout: a silent DUT must fail fast, never hang the run
def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.get_closest_marker("timeout") is None:
            item.add_marker(pytest.mark.timeout(120))

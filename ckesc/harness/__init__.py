"""The conformance harness: lanes, the DUT, requirements, verdicts, the pytest plugin and reports."""

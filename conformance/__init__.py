"""The CKESC 2.1 conformance suites: one module per section of the document.

Run them with ``ckesc run`` (or ``pytest --pyargs conformance``); the ``ckesc`` pytest plugin
provides the ``dut`` fixture and the ``requirement`` marker. Every test cites the requirement ids
it checks (``ckesc/protocol/requirements.toml``).
"""

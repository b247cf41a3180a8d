"""The pytest session: the ``ckesc`` plugin (``plugin.py``, the entry point, registers one module per concern:
collection and preflight, run order, shared cold boots, fixtures and safety, traces, the live bus rules, verdicts,
the session's end), the run's typed record (``state.py``), the one table of the run's options (``options.py``), the
run plan (``schedule.py``), the preflight (``preflight.py``: the bench built from the options as
``ckesc.bench.station`` builds it for every command, and the run's own checks), the trace writer (``trace_files.py``)
and progress (``progress.py``). It holds a bench (``ckesc.bench``) and writes through ``ckesc.reporting``."""

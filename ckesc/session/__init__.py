"""The pytest session: the ``ckesc`` plugin (options, collection and preflight, run order, shared cold
boots, fixtures and safety, traces, the live bus rules, verdicts, the session's end), the run plan
(``schedule.py``), set-up checks (``preflight.py``), per-test traces (``traces.py``) and progress
(``progress.py``). It holds a bench (``ckesc.bench``) and writes through ``ckesc.reporting``."""

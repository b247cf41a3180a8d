"""Driving the device under test: the ``Dut`` a test author holds (``dut.py``), the lanes it talks through
(``lanes.py``: a python-can bus, the real-time emulator; ``sim_lane.py``: simulated time), power control (``lanes.py``'s
``PowerControl`` backends, ``labgrid_power.py``), power epochs and the 120 s window (``epochs.py``), DUT
profiles (``profile.py``, ``profiles/``) and what a test measures and judges (``verdict.py``); and the one way a
bench is built from its options (``station.py``: ``BenchOptions``, ``build``, the ``Station`` it returns; the checks
its options pass, ``checks.py``; the bench proof, ``proof.py``), which the pytest plugin, ``ckesc explore`` and
``ckesc profile`` call alike.

Nothing here knows pytest's session or the reports: ``ckesc.session`` drives it (and so do the explorer and the
command line), ``ckesc.reporting`` never
imports it (and it never imports ``ckesc.reporting``)."""

"""Driving the device under test: the ``Dut`` a test author holds (``dut.py``), the lanes it talks through
(``lanes.py``: simulated time, a python-can bus, the real-time emulator), power control (``lanes.py``'s
``PowerControl`` backends, ``labgrid_power.py``), power epochs and the 120 s window (``epochs.py``), DUT
profiles (``profile.py``, ``profiles/``) and what a test measures and judges (``verdict.py``).

Nothing here knows pytest's session or the reports: ``ckesc.session`` drives it, ``ckesc.reporting`` never
imports it (and it never imports ``ckesc.reporting``)."""

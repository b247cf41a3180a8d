"""Several benches at once: rig files (``rig.py``), the batch run over pytest-xdist (``batch.py``) and
the batch report (``batch_report.py``)."""

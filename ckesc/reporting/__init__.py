"""Reports of a run: the results model (``results.py``), JUnit XML, the text summary and results.json
(``report.py``), the HTML kit and report page (``html_report.py``), failure causes (``causes.py``) and the
comparison of runs (``compare.py``). It reads results, never a bench (``ckesc.bench``)."""

"""Evidence from the bus itself: the rules that hold at all times, judged over a stream of frames.

``rules`` is the sans-IO engine (:class:`BusRules`: one frame in, violations out, per-node statistics
in bounded memory), judging what ``tracker`` works out from the traffic (who is who, which answer answers
which request, the report-interval targets) and keeping what ``findings`` holds; ``timing`` runs that tracker
over one test's frames for the report's plots; ``live`` runs the rules over a suite's lanes; ``candump``
parses candump lines; ``logs`` reads captures (candump, and whatever python-can's ``LogReader`` reads);
``checklog`` checks a capture against them (the library of ``ckesc check-log``).
"""

from .rules import BusRules, Violation

__all__ = ["BusRules", "Violation"]

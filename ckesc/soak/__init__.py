"""``ckesc soak``: hours of flight-like running, watched (issue #31, reading R19).

The sans-IO core: :mod:`.player` plays a flight controller (a RawCommand stream, GET_ESC_ID once a second, periodic
241 and 242 reads: given the time, the frames due and its next deadline); :mod:`.monitor` reads every frame through
the bus reader the suite's live rules and check-log use (:class:`ckesc.evidence.rules.BusRules`) and watches what
comes back, one owner per property taking the reader's events, with streaming statistics only (nothing grows with the run's length but one value per
minute of the R9 trend); :mod:`.statement` words what a run without findings shows (the rule of three). The IO part,
:mod:`.runner`, builds the bench as every command does (:func:`ckesc.bench.station.build`), drives the player on
the lane's clock, feeds the watches, keeps the trace within its disk budget (:mod:`.trace`) and writes the reports (:mod:`.report`).
"""

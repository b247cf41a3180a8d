"""Preflight: everything about a run's set-up that can be wrong before the first test, checked in
about a second, so that a mistake is one clear line (exit status 2) and never hundreds of ERRORs,
a new report directory or a moved ``reports/latest``.

The bench's checks and its building are the bench layer's, as ``ckesc explore`` and ``ckesc profile`` use them
(:func:`ckesc.bench.station.build`: node ids, emulator fault names and variants, option combinations, the DUT
profile, the power commands, labgrid power with its place acquired, the bit-rate command, the bus opened once
within its bound; :mod:`ckesc.bench.checks`). Here is the session's side: the bench options taken from pytest's
once (:class:`~ckesc.bench.station.BenchOptions`), the run's own check (the reports directory, writable), a prompt
that gets past pytest's output capture (``--power manual``), and the station closed at the session's end (a
labgrid place released on every way out). Once the tests are collected, the bench itself is proven on a real bus
(:meth:`~ckesc.bench.station.Station.prove`: who answers GET_ESC_ID, the power switch).
"""

from __future__ import annotations

import os
from contextlib import nullcontext

import pytest

from ..bench.errors import PreflightError
from ..bench.power import Prompt
from ..bench.station import BenchOptions, Station, build
from ..reporting.paths import not_writable

__all__ = ["PreflightError", "prompt", "reports_writable", "run"]


def reports_writable(base: str | os.PathLike) -> None:
    """``base`` is a directory this user can write into, or could make (nothing is made here: a mistake found after
    this one leaves no directory behind), in the words every command uses (:func:`ckesc.reporting.paths.not_writable`)."""
    said = not_writable(base, "--reports", "reports directory")
    if said:
        raise PreflightError(said)


def run(config: pytest.Config) -> Station:
    """The run's bench, built from its options (the first mistake raises :class:`PreflightError`), and closed by
    pytest's cleanup at the session's end."""
    reports = config.getoption("ckesc_reports")
    station = build(BenchOptions.of(config.getoption), prompt=prompt(config),
                    before_opening=(lambda: reports_writable(reports)) if reports else None)
    config.add_cleanup(station.close)
    return station


def prompt(config: pytest.Config) -> Prompt:
    """``--power manual``'s question to the operator, asked with pytest's output capture suspended."""

    def ask(text: str) -> None:
        capman = config.pluginmanager.getplugin("capturemanager")
        with capman.global_and_fixture_disabled() if capman else nullcontext():
            input(f"\n>>> {text} ")

    return ask


"""The protocol's families are written once, in the catalogue, and the suite's tests that range over one take it from
there (issue #28): the RawCommand frames, the MSG1..MSG3 reports and their interval fields appear as a literal
nowhere else, and every persisted setting's write is checked while reporting is suspended (4.4.2-3, R12). Read with
``ast`` and the source, without a suite run."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import ckesc
import conformance
from ckesc.protocol import catalogue as cat

ROOTS = (Path(ckesc.__file__).parent, Path(conformance.__file__).parent)
CATALOGUE = Path(cat.__file__).parent  # the catalogue package, every module of it
#: a family written out as a literal: its members in a row, quoted, comma-separated
FAMILIES = {name: re.compile(r",\s*".join(f"[\"']{m}[\"']" for m in members))
            for name, members in (("THROTTLE_FRAMES", cat.THROTTLE_FRAMES), ("REPORT_FRAMES", cat.REPORT_FRAMES),
                                  ("INTERVAL_FIELDS", cat.INTERVAL_FIELDS))}


def test_no_family_is_written_out_outside_the_catalogue():
    found = [f"{path.relative_to(path.parents[2])}:{text.count(chr(10), 0, m.start()) + 1}: {name}"
             for root in ROOTS for path in sorted(root.rglob("*.py")) if CATALOGUE not in path.parents
             for text in [path.read_text(encoding="utf-8")]
             for name, pattern in FAMILIES.items() for m in pattern.finditer(text)]
    assert found == [], "write these as the catalogue's family (ckesc.protocol.catalogue): " + "; ".join(found)


def test_the_families_counter_catches_a_literal():
    assert FAMILIES["THROTTLE_FRAMES"].search('X = ("raw_command_14b", "raw_command_12b", "raw_command_10b")')
    assert FAMILIES["REPORT_FRAMES"].search("for n in ('msg1', 'msg2', 'msg3'):")
    assert not FAMILIES["REPORT_FRAMES"].search('("msg1", 0.02), ("msg2", 0.1), ("msg3", 0.5)')


def _tests(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return {n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")}


def test_every_persisted_setting_is_checked_while_suspended():
    """4.4.2-3 / R12 for every writer of :data:`~ckesc.protocol.catalogue.PERSISTED_SETTINGS`: the ones a test can write
    at any time are the parameters of test_settings_do_not_change_while_suspended (section 4.4.2); Set ID and Set
    Baud (the 120 s window, R11; Set Baud read back by the rate after a power-up) have a test of that name in their
    own sections. A setting added to the table without one fails here."""
    from conformance.test_s4_4_2_msg_control import HELD

    assert set(HELD) == {s.writer for s in cat.PERSISTED_SETTINGS if not s.window}
    root = Path(conformance.__file__).parent
    for s in cat.PERSISTED_SETTINGS:
        if not s.window:
            continue
        section = cat.spec(s.writer).section
        (module,) = root.glob(f"test_s{section.replace('.', '_')}_*.py")
        assert f"test_{s.writer}_while_suspended_changes_nothing" in _tests(module), (s.writer, module.name)


def test_the_neighbour_check_moves_every_persisted_setting_outside_the_window():
    from conformance.settings import NEIGHBOURS

    assert [(name, keys) for name, (keys, _) in NEIGHBOURS.items()] == [
        (s.name, s.keys) for s in cat.PERSISTED_SETTINGS if not s.window]

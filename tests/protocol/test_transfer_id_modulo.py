"""The transfer-id modulo is written once (issue #35, item 6; F2/F3): ``ckesc/protocol/transfer.py`` says a transfer
id is five bits of the tail byte counting modulo 32, and every other module calls its helpers (``tail_transfer_id``,
``next_transfer_id``, ``TAIL_BYTES``, ``TRANSFER_ID_MODULO``). The source of ``ckesc/`` and ``conformance/`` is read
with ``ast``; every ``x % 32`` and ``x & 0x1F`` (``& 31``) elsewhere fails here unless

* it reads a 29-bit id's priority (``(can_id >> 24) & 0x1F``, the five bits above bit 24: F1's, not a transfer id),
* or :data:`NOT_TRANSFER_IDS` says which other five-bit fact it is,
* or :data:`PENDING` names it in ``ckesc/soak/`` or ``ckesc/explore/``, left to their owners.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OWNER = "ckesc/protocol/transfer.py"
#: (file, expression) -> which five-bit fact it is, when it is no transfer id
NOT_TRANSFER_IDS: dict[tuple[str, str], str] = {
    ("ckesc/emulator/esc_answers.py", "self.state.led_blink & 31"): "MSG Config's five-bit led_blink field",
}
#: (file, expression) -> the line it was on when listed: transfer ids of soak/ and explore/, left to their owners; an
#: entry goes when its owner calls transfer.py's helpers there
PENDING: dict[tuple[str, str], str] = {
    ("ckesc/explore/oracle.py", "data[-1] & 31"): "ckesc/explore/oracle.py:150",
}


def _is_priority(node: ast.BinOp) -> bool:
    left = node.left
    return isinstance(node.op, ast.BitAnd) and isinstance(left, ast.BinOp) and isinstance(left.op, ast.RShift) \
        and isinstance(left.right, ast.Constant) and left.right.value == 24


def _modulo_32(node: ast.AST) -> bool:
    if not isinstance(node, ast.BinOp) or not isinstance(node.right, ast.Constant) or type(node.right.value) is not int:
        return False
    return (isinstance(node.op, ast.Mod) and node.right.value == 32) or \
        (isinstance(node.op, ast.BitAnd) and node.right.value == 31 and not _is_priority(node))


def _places() -> list[tuple[str, str, int]]:
    """(file, expression as ``ast.unparse`` writes it, line) of every ``% 32`` and ``& 0x1F`` but the owner's."""
    out = []
    for base in ("ckesc", "conformance"):
        for p in sorted((ROOT / base).rglob("*.py")):
            name = p.relative_to(ROOT).as_posix()
            if name == OWNER:
                continue
            tree = ast.parse(p.read_text(encoding="utf-8"), str(p))
            out += [(name, ast.unparse(n), n.lineno) for n in ast.walk(tree) if _modulo_32(n)]
    return out


def test_the_transfer_id_modulo_is_written_once():
    excused = NOT_TRANSFER_IDS.keys() | PENDING.keys()
    by_hand = [f"{f}:{line}: {expr}" for f, expr, line in _places() if (f, expr) not in excused]
    assert not by_hand, f"a transfer id's modulo written by hand (call {OWNER}'s helpers): {by_hand}"


def test_the_allow_lists_name_places_still_there():
    places = {(f, expr) for f, expr, _ in _places()}
    assert all(f.startswith(("ckesc/soak/", "ckesc/explore/")) for f, _ in PENDING)
    gone = sorted((NOT_TRANSFER_IDS.keys() | PENDING.keys()) - places)
    assert not gone, f"no longer written: remove these from the allow-lists: {gone}"


def test_the_scan_sees_a_transfer_id_and_passes_a_priority():
    assert _modulo_32(ast.parse("(tid + 1) % 32", mode="eval").body)
    assert _modulo_32(ast.parse("data[-1] & 0x1F", mode="eval").body)
    assert not _modulo_32(ast.parse("(can_id >> 24) & 0x1F", mode="eval").body)

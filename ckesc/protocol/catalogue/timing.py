"""The catalogue's timing facts: the report interval's unit and range (Set/Get Freq, 4.4.22), the answer slots
(R2) and the 64 ms bound, the comm-loss timeout (R8), the configuration window (R11) and a restart's allowance
(R9a). A judgement that needs a time limit takes it from here (``ckesc/protocol/judgements.py``), never retypes it.
"""

from __future__ import annotations

#: Report interval unit of Set/Get Freq and 242 (4.4.22): value x 2 ms.
INTERVAL_UNIT_S = 0.002
REPORT_INTERVAL_RANGE = (10, 250)

#: The answer slots of MSG Control and GET_ESC_ID, and the bound every answer keeps.
ANSWER_SLOT_S = 0.002  # R2: answer after (node_id % 32) x 2 ms
ANSWER_DELAY_MAX_S = 0.064  # 4.4.2 clarification 4, 4.4.3 clarification 4
ANSWER_SLOTS = round(ANSWER_DELAY_MAX_S / ANSWER_SLOT_S)  # R2: the slots (node_id % 32) tile the 64 ms


def answer_slot_s(node_id: int) -> float:
    """R2: when node ``node_id``'s answer slot (MSG Control, GET_ESC_ID) starts after the request."""
    return (node_id % ANSWER_SLOTS) * ANSWER_SLOT_S


COMM_LOSS_TIMEOUT_S = 0.200  # 4.4.4 clarification 3 (R8)
CONFIG_WINDOW_S = 120.0  # 4.3.2 table, R11: Set ID / Set Baud valid 120 s after power-up
RESTART_SLACK_MIN_S = 0.003  # R9a: the first report after a restart within one interval + max(3 ms, interval / 4)


def restart_limit_s(interval: float) -> float:
    """R9a (READING): the first report of a type after a restart (power-up, a resume, leaving MSG_EXP mode, CAN
    Test off) comes within its interval plus a slack of max(3 ms, a quarter of it); after a Set Freq write,
    ``interval`` is the longer of its old and new interval."""
    return interval + max(RESTART_SLACK_MIN_S, interval / 4)

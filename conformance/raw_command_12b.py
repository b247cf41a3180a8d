"""RawCommand_12b (4.4.16) as a throttle format: the :class:`~conformance.throttle.RawCommand` that
section 4.4.16 tests, and with which section 4.4.18 checks that Set ID's channel selects the throttle
value; the values it carries, one per channel (not a section: no tests here).
"""

from ckesc.protocol import catalogue as cat
from ckesc.protocol.codecs import codec_for

from .throttle import RawCommand

NAME = "raw_command_12b"
_CODEC = codec_for(cat.spec(NAME).layouts[0])
_SIZE = cat.spec(NAME).layouts[0].size
PER_GROUP = len(_CODEC.decode(bytes(_SIZE))["channels"])  # 4.4.16-3: four channels per group
RAW_MAX = max(_CODEC.decode(b"\xff" * _SIZE)["channels"])  # 4.4.16-2: 12 bits, 0..4095
GROUPS = cat.THROTTLE_GROUPS  # 4.4.16-3: group ids 1..5
FORMAT = RawCommand(NAME, per_frame=PER_GROUP, groups=tuple(GROUPS), requirement="4.4.16-3")
#: one distinct value per channel 1..20, inside 0..2000, whose nibbles differ across p1/p4 (R4)
VALUES = {c: 198 + 64 * c for c in cat.THROTTLE_CHANNELS}

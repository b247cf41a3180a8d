"""ckesc: conformance suite, emulator and tools for the CKESC UAVCAN Protocol 2.1."""

__version__ = "0.1.0"

#: The one revision of the vendor document this code base follows (module names and quotes are pinned to it).
SPEC_REVISION = "CKESC UAVCAN Protocol 2.1 (2024/10/11)"

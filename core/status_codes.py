"""OPC UA status codes (IEC 62541-4), the one quality model of every stored sample."""

from __future__ import annotations

GOOD = 0x00000000
BAD = 0x80000000
"""Generic Bad (the top bit set means Bad)."""
BAD_COMMUNICATION_ERROR = 0x80050000
BAD_TIMEOUT = 0x800A0000
BAD_NO_COMMUNICATION = 0x80310000
"""Gap marker: the connection to the source was lost at this time."""
BAD_DEVICE_FAILURE = 0x808B0000
BAD_SENSOR_FAILURE = 0x808C0000
BAD_OUT_OF_RANGE = 0x803C0000
BAD_DATA_ENCODING_INVALID = 0x80380000
"""A malformed register or a non-finite number."""


def is_bad(status: int) -> bool:
    """Bad quality (severity bits 10): the value must not be used."""
    return bool(status & 0x80000000)

"""The sample row every connector produces and the store keeps."""

from __future__ import annotations

from typing import NamedTuple


class Sample(NamedTuple):
    """One value of one tag.

    ``ts_us``: source timestamp (µs since 1970 UTC); ``recv_us``: when plantcheck received it;
    ``value``: None whenever ``status`` is Bad (OPC UA status code, 0 = Good).
    """

    tag_id: int
    ts_us: int
    recv_us: int
    value: float | None
    status: int

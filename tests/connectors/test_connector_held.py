"""Held tags (a polled source's SP and mode) are passed on when they change, after a gap marker
and at least every ``HELD_REFRESH_S``; other tags every sample. The filter of
``DeviceConnector.emit`` (the protocol side is tested against the real simulator in
test_ingest.py)."""

from __future__ import annotations

from collections.abc import Sequence

from plantcheck.connectors.base import HELD_REFRESH_S, DeviceConnector
from plantcheck.core.samples import Sample
from plantcheck.core.status_codes import BAD_NO_COMMUNICATION, BAD_SENSOR_FAILURE, GOOD

SP, PV = 1, 2
S = 1_000_000


class Emitter(DeviceConnector):
    """A connector whose samples come from the test (no device)."""

    async def connect(self) -> None:
        pass

    async def collect(self) -> None:
        pass

    async def close(self) -> None:
        pass


def test_held_tags_are_passed_on_when_they_change() -> None:
    stored: list[Sample] = []

    def sink(rows: Sequence[Sample]) -> None:
        stored.extend(rows)

    c = Emitter("plc", sink, [SP, PV], held=[SP])
    refresh = int(HELD_REFRESH_S) * S
    polls = [
        (0, 50.0, GOOD),
        (1 * S, 50.0, GOOD),  # unchanged: dropped
        (2 * S, 55.0, GOOD),  # a set-point step
        (3 * S, 55.0, GOOD),
        (4 * S, None, BAD_SENSOR_FAILURE),  # status change
        (5 * S, None, BAD_SENSOR_FAILURE),
        (6 * S, 55.0, GOOD),
        (6 * S + refresh - 1, 55.0, GOOD),  # unchanged, within the refresh: dropped
        (6 * S + refresh, 55.0, GOOD),  # refreshed
    ]
    for t, v, status in polls:
        c.emit([Sample(SP, t, t, v, status), Sample(PV, t, t, 1.0, GOOD)])
    assert [r.ts_us for r in stored if r.tag_id == PV] == [t for t, _, _ in polls]
    kept = [(r.ts_us, r.value) for r in stored if r.tag_id == SP]
    assert kept == [(0, 50.0), (2 * S, 55.0), (4 * S, None), (6 * S, 55.0), (6 * S + refresh, 55.0)]
    c.mark_gap()  # after a gap marker the value is stored again, after the marker
    c.emit([Sample(SP, 1, 1, 55.0, GOOD)])
    assert stored[-2].status == BAD_NO_COMMUNICATION and stored[-1].value == 55.0
    assert stored[-1].ts_us > stored[-2].ts_us

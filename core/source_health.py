"""A data source's health, as connectors report it, the store keeps it and the API shows it.

Times are µs since 1970-01-01 UTC.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SourceHealth:
    """A snapshot of one source for the API and the metrics (times in µs since the epoch).

    ``state`` is ``up`` while data flows, ``down`` from the first failure until data flows
    again, ``unknown`` before the first connection has delivered or failed.
    """

    name: str
    protocol: str
    state: str
    since_us: int | None
    last_good_sample_us: int | None
    failures: int
    last_error: str

    def down_for_s(self, now_us: int) -> float:
        """Seconds the source has been down (0 when it is not)."""
        if self.state != "down" or self.since_us is None:
            return 0.0
        return max(0.0, (now_us - self.since_us) / 1e6)

"""Plant time against the server's clock on the loop page (issue 47): said when they differ."""

from __future__ import annotations

from plantcheck.api.web import plant_clock_note

NOW = 1_800_000_000_000_000
H = 3_600_000_000


def test_plant_time_far_from_the_server_clock_is_said() -> None:
    assert plant_clock_note(None, NOW) == ""
    assert plant_clock_note(NOW - 60_000_000, NOW) == ""  # a minute: ordinary lag
    ahead = plant_clock_note(NOW + 5 * H, NOW)
    assert "5.0 h ahead of this server's clock" in ahead and "simulator" in ahead
    assert "10 min behind" in plant_clock_note(NOW - H // 6, NOW)

"""Window checks (methods.md §1): each reason a window cannot be judged."""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis import diagnose
from plantcheck.diagnosis.window import check_window

RNG = np.random.default_rng(0)
N = 2000
PV = 50 + np.cumsum(RNG.normal(0, 0.05, N)) + RNG.normal(0, 0.2, N)
OP = 40 + np.cumsum(RNG.normal(0, 0.05, N))


def test_clean_window_passes() -> None:
    rep = check_window(PV, OP)
    assert rep.verdict is None
    assert any("no SP column" in n for n in rep.notes)


def test_short_gaps_filled_long_missing_is_data_quality() -> None:
    pv = PV.copy()
    pv[100:103] = np.nan
    rep = check_window(pv, OP)
    assert rep.verdict is None and np.isfinite(rep.pv).all()
    pv[200:400] = np.nan
    assert check_window(pv, OP).verdict == "data_quality"


def test_manual_mode_from_mode_signal_and_from_frozen_op() -> None:
    auto = np.ones(N, dtype=bool)
    auto[: N // 2] = False
    assert check_window(PV, OP, auto=auto).verdict == "manual_mode"
    assert check_window(PV, np.full(N, 37.0)).verdict == "manual_mode"


def test_manual_time_past_what_a_window_bridges_reads_manual_mode_not_missing_data() -> None:
    """Manual samples are left out as gaps (methods §1 keeps AUTO samples only, from 90 %); past
    the 5 % a window may bridge, the cause is the manual time, not a record with holes."""
    auto = np.ones(N, dtype=bool)
    auto[900:1060] = False  # 8 % in manual
    rep = check_window(PV, OP, auto=auto)
    assert rep.verdict == "manual_mode"
    assert any("8.0 % of the window in manual" in n for n in rep.notes), rep.notes
    pv = PV.copy()
    pv[900:1060] = np.nan  # the same share missing from the record itself
    assert check_window(pv, OP).verdict == "data_quality"
    auto[900:1000] = True  # 3 % in manual: bridged and judged
    assert check_window(PV, OP, auto=auto).verdict is None


def test_a_window_90_percent_in_automatic_is_judged_on_its_longest_automatic_stretch() -> None:
    """Methods §1 judges a window in automatic for 90 % of it; past the 5 % a window may
    bridge, the chain judges its longest automatic stretch alone (times from its start)."""
    auto = np.ones(N, dtype=bool)
    auto[700:860] = False  # 8 % in manual
    d = diagnose(PV, OP, 2.0, auto=auto)
    assert d.cause != "manual_mode" and d.samples == N - 860
    assert "judged on its longest automatic stretch, 1720-4000 s (2280 s)" in d.notes[0]
    auto[100:300] = False  # 18 % in manual
    assert diagnose(PV, OP, 2.0, auto=auto).cause == "manual_mode"


def test_an_output_held_still_under_a_live_pv_reads_as_manual_without_the_mode_flag() -> None:
    """No controller in automatic holds OP bit for bit while PV moves: an operator did
    (issue 46 item 1); a hold to the window's end, a quantised OP or a clamp are not that."""
    op = OP.copy()
    op[900:1060] = op[900]  # 8 % held mid-range, then the controller moves OP again
    rep = check_window(PV, op)
    assert rep.verdict == "manual_mode", rep.notes
    assert any("OP held exactly still on 8.0 %" in n for n in rep.notes), rep.notes
    # the chain judges the longest automatic stretch of a window 90 % in automatic
    d = diagnose(PV, op, 1.0)
    assert d.cause != "manual_mode" and d.samples == N - 1060, d.notes
    assert d.notes[0].startswith(
        "8.0 % of the window in manual (OP held exactly still while PV kept moving): judged"
    ), d.notes
    longer = op.copy()
    longer[100:400] = longer[100]  # 23 % in manual: less than methods §1's 90 % in automatic
    assert diagnose(PV, longer, 1.0).cause == "manual_mode"
    op[1000:1060] = OP[1000:1060]  # 5 % held: bridged and judged, with the note
    rep = check_window(PV, op)
    assert rep.verdict is None and rep.indices["held_output_fraction"] == 0.05, rep.notes
    tail = OP.copy()
    tail[1700:] = tail[1700]  # an export holding its last stored value
    assert "held_output_fraction" not in check_window(PV, tail).indices
    coarse = np.round(op / 0.5) * 0.5  # an OP recorded in 0.5 % steps holds everywhere
    assert "held_output_fraction" not in check_window(PV, coarse).indices
    clamp = OP.copy()
    clamp[900:1060] = OP.max() + 1.0  # at the window's own extreme: a limit, not an operator
    assert "held_output_fraction" not in check_window(PV, clamp).indices


def test_an_unflagged_manual_stretch_is_found_under_a_compressed_pv_or_beside_a_clamp() -> None:
    """A historian's compressed PV changes on a fifth of the steps, held OP or not: PV needs
    to move inside the hold about as often as elsewhere, not on half the steps. A saturated
    loop's OP rests at its limit and leaves it for a sample at times: those samples are the
    clamp's, not steps where OP should move."""
    op = OP.copy()
    op[600:1000] = op[600]  # 20 % in manual, no mode tag
    held_pv = PV[np.arange(N) // 5 * 5]  # a value stored every fifth sample, held between
    rep = check_window(held_pv, op)
    assert rep.verdict == "manual_mode" and rep.indices["held_output_fraction"] == 0.2, rep.notes
    clamped = op.copy()
    top = float(OP.max()) + 1.0
    clamped[1100:1900] = top  # at its limit 40 % of the window,
    clamped[1100:1900:40] = top - 0.01  # leaving it for a sample now and then
    rep = check_window(PV, clamped)
    assert rep.indices["held_output_fraction"] == 0.2, rep.notes
    stalled = PV.copy()
    stalled[600:1000] = stalled[600]  # PV still too: a stalled record, not an operator
    assert "held_output_fraction" not in check_window(stalled, op).indices


def _frozen_at(start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
    """PV frozen over [start, stop) as the controller sees it: its error is constant there,
    so its integral action ramps OP on a straight line."""
    pv, op = PV.copy(), OP.copy()
    pv[start:stop] = pv[start]
    op[start:stop] = op[start] + 0.01 * np.arange(stop - start)
    op[stop:] += op[stop - 1] - OP[stop - 1]
    return pv, op


def test_a_transmitter_frozen_for_part_of_the_window_is_left_out_and_named() -> None:
    """PV repeating its value bit for bit while OP ramps without its noise (issue 46 items 1
    and 7): not a stuck phase, a measurement the controller saw frozen."""
    pv, op = _frozen_at(900, 1060)  # 8 %: more than a window may bridge
    rep = check_window(pv, op)
    assert rep.verdict == "data_quality", rep.notes
    assert any("transmitter froze" in n for n in rep.notes), rep.notes
    assert any("the transmitter frozen on 8.0 %" in n for n in rep.notes), rep.notes
    pv, op = _frozen_at(900, 960)  # 3 %: bridged, judged, noted
    op[300:302] = np.nan  # a gap in OP elsewhere leaves the rest to read
    rep = check_window(pv, op)
    assert rep.verdict is None and rep.indices["frozen_pv_fraction"] == 0.03, rep.notes
    assert rep.bridged is not None and rep.bridged[900:960].all()
    held = PV.copy()
    held[900:1060] = held[900]  # a historian holding a live PV: OP keeps its noise
    assert "frozen_pv_fraction" not in check_window(held, OP).indices
    pv, op = _frozen_at(900, 1060)
    drawn = np.interp(np.arange(N), np.arange(0, N, 20), op[::20])  # an interpolated export
    assert "frozen_pv_fraction" not in check_window(pv, drawn).indices


def test_saturation_needs_a_clamped_output() -> None:
    op = np.where(np.arange(N) < 1500, 100.0, OP)
    assert check_window(PV, op).verdict == "saturation"
    # an OP that only wanders near 0 (scaled data) is not clamped
    assert check_window(PV, 0.01 * (OP - 40)).verdict is None


def test_frozen_and_quantised_pv() -> None:
    assert check_window(np.full(N, 3.0), OP).verdict == "data_quality"
    coarse = np.round(PV / 5) * 5  # only a few levels
    assert check_window(coarse, OP).verdict == "data_quality"
    # a steady loop on a coarse historian: five levels are still judged, with a note
    steady = 50 + np.round(RNG.normal(0, 0.8, N))
    rep = check_window(steady, OP, np.full(N, 50.0))
    assert rep.verdict is None and rep.quantised, rep.notes


def _tracking(sp: np.ndarray, tau: float = 50.0) -> np.ndarray:
    """A PV that follows its set point through a first-order lag of ``tau`` samples."""
    pv = np.empty(sp.size)
    pv[0] = sp[0]
    a = np.exp(-1.0 / tau)
    for k in range(1, sp.size):
        pv[k] = a * pv[k - 1] + (1 - a) * sp[k]
    return pv + RNG.normal(0, 0.05, sp.size)


def test_sp_step_response_is_left_out_and_the_settled_stretch_analysed() -> None:
    sp = np.where(np.arange(N) < 300, 50.0, 55.0)
    rep = check_window(_tracking(sp), OP, sp)
    assert rep.verdict is None
    # the response to a 5-unit step through a 50-sample lag settles within ~115 samples
    assert 380 < rep.segment[0] < 460 and rep.segment[1] == N, rep.segment
    assert any("settled stretch" in n for n in rep.notes), rep.notes


def test_frequent_sp_steps_do_not_make_a_window_unusable() -> None:
    """Four steps in 2,000 samples (issue 25): judged on the longest settled stretch."""
    sp = 50.0 + np.select(
        [np.arange(N) < 400, np.arange(N) < 800, np.arange(N) < 1200, np.arange(N) < 1600],
        [0.0, 3.0, -2.0, 4.0],
        1.0,
    )
    rep = check_window(_tracking(sp), OP, sp)
    assert rep.verdict is None and not rep.sp_limited, rep.notes
    assert rep.segment[1] - rep.segment[0] >= 300
    # every settled stretch long enough is offered, longest first, for segment-by-segment tests
    assert rep.segments[0] == rep.segment, rep.segments
    lengths = [b - a for a, b in rep.segments]
    assert lengths == sorted(lengths, reverse=True) and min(lengths) >= 300
    # steps every 150 samples leave nothing long enough: said with the number
    dense = 50.0 + 3.0 * ((np.arange(N) // 150) % 2)
    rep = check_window(_tracking(dense), OP, dense)
    assert rep.verdict == "insufficient_data" and rep.sp_limited
    assert any("leave no settled stretch of 300 samples" in n for n in rep.notes), rep.notes


def test_an_output_limit_anywhere_is_a_clamp() -> None:
    """A DCS limit at 55 %: OP rests exactly there while PV stays below SP."""
    k = np.arange(N)
    op = np.where(k < 600, 45 + 10 * k / 600, 55.0)
    pv = np.where(k < 600, 50.0, 50.0 - 4 * (1 - np.exp(-(k - 600) / 80.0)))
    pv = pv + RNG.normal(0, 0.05, N)
    rep = check_window(pv, op, np.full(N, 50.0))
    assert rep.verdict == "saturation", rep.notes
    assert rep.indices["op_limit"] == 55.0 and rep.indices["saturation_fraction"] > 0.6
    # a slow output that only passes its maximum is no clamp
    smooth = 50 + 5 * np.sin(2 * np.pi * k / N)
    assert check_window(pv, smooth, np.full(N, 50.0)).indices["saturation_fraction"] == 0.0


def test_a_constant_output_with_pv_held_off_set_point_is_saturation() -> None:
    pv = 46.0 + RNG.normal(0, 0.05, N)
    rep = check_window(pv, np.full(N, 72.0), np.full(N, 50.0))
    assert rep.verdict == "saturation", rep.notes


def test_diagnose_rejects_unknown_loop_type() -> None:
    try:
        diagnose(PV, OP, 1.0, loop_type="valve")
    except ValueError as exc:
        assert "loop_type" in str(exc)
    else:  # pragma: no cover
        raise AssertionError("no error")

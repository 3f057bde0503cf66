"""Loops simulated side by side give the records ``simulate_loop`` gives, bit for bit, so a
corpus drawn either way is the same corpus (the cached evidence, the shipped model file)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from plantcheck.simulator.actuator import ActuatorSpec
from plantcheck.simulator.batch_loop import _batch, simulate_loops
from plantcheck.simulator.corpus import CLASSES, FAMILIES, _draw, draw_case, draw_cases
from plantcheck.simulator.loop import LoopConfig, LoopRecord, simulate_loop


def same(a: LoopRecord, b: LoopRecord) -> bool:
    """Every array equal to the bit: values, NaNs and the signs of zeros."""
    return all(
        np.array_equal(x.view(np.int64), y.view(np.int64))
        for x, y in ((getattr(a, f), getattr(b, f)) for f in ("t", "sp", "pv", "op", "mv"))
    )


def corpus_configs() -> list[LoopConfig]:
    """Corpus windows until every process, valve, recording and limit family and a drifting
    friction for every sticky model are among them, with their twins: the sticky valves from
    windows that show their label (the stem sticks and slips), the rest from first draws,
    shortened, with warm-ups that end the loops at different samples."""
    plain = {(k, v) for k in ("process", "recording", "limit") for v in FAMILIES[k]}
    sticky = {(f, v) for f in ("steady", "drifting") for v in FAMILIES["valve"][1:]}
    cfgs: list[LoopConfig] = []
    index = 0
    while plain and index < 2000:
        case = _draw(np.random.default_rng([11, index, 0]), index, CLASSES[index % 6])
        index += 1
        seen = {(k, case.family[k]) for k in ("process", "recording", "limit")}
        if seen & plain:
            plain -= seen
            short = min(case.config.n_samples, 600)
            warm = min(case.config.warmup_samples, 50 + 7 * index % 400)
            for cfg in (case.config, case.twin):
                if cfg is not None:
                    cfgs.append(replace(cfg, n_samples=short, warmup_samples=warm))
    index = 1
    while sticky and index < 2000:
        case, _ = draw_case(11, index)
        index += 6  # stiction windows only
        cfg = case.config
        key = ("drifting" if cfg.friction_spread > 0 else "steady", cfg.valve)
        if key in sticky and cfg.n_samples + cfg.warmup_samples <= 6000:
            sticky.discard(key)
            cfgs.append(cfg)
    assert not plain and not sticky, f"no corpus window of {sorted(plain | sticky)}"
    return cfgs


def slips(rec: LoopRecord) -> int:
    moves = np.abs(np.diff(rec.mv)) > 1e-9
    return int(np.sum(moves[1:] & ~moves[:-1]))


def test_a_batch_gives_every_loop_the_record_it_gets_alone() -> None:
    cfgs = corpus_configs()
    alone = [simulate_loop(c) for c in cfgs]
    together = _batch(cfgs)
    differ = [c.valve for c, a, b in zip(cfgs, alone, together, strict=True) if not same(a, b)]
    assert not differ
    # every sticky model stuck and slipped in the batch, with and without drifting friction
    moved = {(c.valve, c.friction_spread > 0) for c, r in zip(cfgs, together, strict=True)
             if c.valve != "linear" and slips(r) >= 2}  # fmt: skip
    assert len(moved) == 8


def test_manual_and_frozen_stretches_are_stepped_in_the_batch_as_alone() -> None:
    """Stretches of every kind (from the first sample, to the record's end, a freeze inside a
    manual stretch and one across its end, back to back) on loops of every family, sticky
    valves and clamped outputs among them, the loops ending at different samples."""
    cfgs = corpus_configs()
    kinds: list[dict[str, tuple[tuple[float, float], ...]]] = [
        {"manual": ((0.0, 0.2),)},
        {"manual": ((0.3, 0.5),), "frozen_pv": ((0.35, 0.4), (0.45, 0.6))},
        {"frozen_pv": ((0.0, 0.1), (0.1, 0.3))},
        {"manual": ((0.1, 0.2), (0.2, 0.3)), "frozen_pv": ((0.8, 1.0),)},
        {"frozen_pv": ((0.5, 0.7),), "manual": ((0.6, 1.0),)},
    ]
    stretched = []
    for i, c in enumerate(cfgs):
        span = c.n_samples * c.sample_time_s
        kind = kinds[i % len(kinds)]
        stretched.append(replace(c, **{k: tuple((a * span, b * span) for a, b in v)
                                       for k, v in kind.items()}))  # fmt: skip
    stretched.append(cfgs[0])  # a loop without stretches among them
    alone = [simulate_loop(c) for c in stretched]
    together = _batch(stretched)
    differ = [i for i, (a, b) in enumerate(zip(alone, together, strict=True)) if not same(a, b)]
    assert not differ
    assert all(np.ptp(r.pv) > 0 for r in together)  # not every loop frozen throughout


def test_loops_the_batch_cannot_step_are_simulated_alone_in_place() -> None:
    """An actuator model or a valve characteristic is stepped by ``simulate_loop``; the
    records come back in the order asked, however the loops were batched."""
    cfgs = corpus_configs()[:40]
    cfgs[3] = replace(cfgs[3], characteristic="equal_percentage")
    cfgs[7] = replace(cfgs[7], actuator=ActuatorSpec())
    got = simulate_loops(cfgs)
    assert all(same(simulate_loop(c), r) for c, r in zip(cfgs, got, strict=True))


def test_windows_drawn_side_by_side_are_the_windows_drawn_one_by_one() -> None:
    """Windows that need several draws to show their label included (a sticky valve that
    never slips twice, a fault that does not stand out of its twin)."""
    indices = list(range(30, 66))  # more than SPECULATIVE_TWINS: twins simulated ahead
    together = draw_cases(5, indices)
    for index, (case, rec) in zip(indices, together, strict=True):
        one, rec_one = draw_case(5, index)
        assert one == case
        assert same(rec_one, rec)

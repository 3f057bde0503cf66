"""Many closed loops simulated side by side, each sample a few dozen numpy operations over all.

``simulate_loop`` steps one loop in a Python loop, about 3 µs a sample with its inputs and
record, so a training corpus of 64,000 windows, their retries and their fault-free twins
(issue 46) spent most of its hours there. Here the loops of a batch advance together, each
state an array over the loops, longest first, and a loop leaves the batch when it ends: a
sample costs about 38 µs whatever the batch's size and 0.26 µs more for each loop in it
(2026-11-30, 2 cores). ``simulate_loops`` weighs that against stepping the loops alone.

Every operation is the one ``ClosedLoop.run`` and the valve models make, in the same order,
on the same float64 values, so each record is the same to the bit as ``simulate_loop``'s, and
a corpus drawn either way is the same corpus (a test holds every valve model, process kind
and recording to that). A branch becomes a mask, both sides computed and the taken side kept;
or, where a loop never takes it, neutral constants whose result can differ from the branch's
only in the sign of a zero that is then added to a non-zero value.

Loops with an actuator model or a non-linear flow characteristic (the served plant's, never
the corpus') are stepped one at a time by ``simulate_loop``. Manual and frozen-transmitter
stretches (``LoopConfig.manual``, ``frozen_pv``) are masks over the batch's samples: the
operator takes over the last OP where a manual stretch's segment starts, the transmitter holds
the last reading where a frozen one starts, as ``loop._run_stretches`` switches between runs.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from plantcheck.simulator.loop import (
    BoolArray,
    FloatArray,
    LoopConfig,
    LoopRecord,
    delay_samples,
    loop_inputs,
    loop_record,
    simulate_loop,
    stretch_samples,
)

STICKY_MODELS = ("kano", "he", "choudhury", "backlash")
"""The sticky valve models ``loop.make_valve`` builds (``LoopConfig.valve``)."""

BATCH_SAMPLES = 8_000_000
"""Samples (warm-up included) of one batch at most, and of one pass of ``corpus.iter_cases``:
with their inputs, outputs and records about 120 bytes a sample, so a corpus worker peaks near
1 GB (2 workers drawing shapes: 2.4 GB in use at the peak against 0.5 before, 73 windows a
second; 20 million: 4.7 GB and 81 a second, and a machine with more cores runs a worker on
each)."""

STEP_COST = 12.0
"""What a sample of a batch costs whatever its size (numpy's call overhead), in samples of
``simulate_loop``; each sticky valve model among the loops adds ``STICKY_STEP_COST``."""
STICKY_STEP_COST = 16.0
LOOP_SAMPLE_COST = 0.085
"""What each loop's sample adds to a batch's, in samples of ``simulate_loop``. Read
2026-11-30 off the batches of a 2,000-window draw on 2 cores (inputs and records taken out): a
batch's sample about 38 µs, each loop's 0.26 µs, each sticky model's about 50 µs, against
about 3.1 µs a sample for ``simulate_loop``; ``benchmarks/corpus_speed.py --costs`` reads
them again, roughly. A sticky valves' batch then rarely pays: its models' steps cost about
what stepping its loops alone does."""


def simulate_loops(cfgs: Sequence[LoopConfig]) -> list[LoopRecord]:
    """``[simulate_loop(c) for c in cfgs]``, the same records bit for bit. The loops with a
    sound valve, and apart those with a sticky one, are simulated side by side in batches of
    ``BATCH_SAMPLES`` at most, longest first, except where a batch would cost more than its
    loops alone: a batch's sample costs the same whatever its size, so a few loops, or the
    few much longer than the rest, are stepped one at a time."""
    out: list[LoopRecord | None] = [None] * len(cfgs)
    groups: dict[bool, list[int]] = {False: [], True: []}
    for i, c in enumerate(cfgs):
        if c.actuator is not None or c.characteristic != "linear":
            out[i] = simulate_loop(c)
        else:
            groups[c.valve != "linear"].append(i)
    for members in groups.values():
        members.sort(key=lambda i: -(cfgs[i].n_samples + cfgs[i].warmup_samples))
        while members:
            size, total = 0, 0
            while size < len(members) and (size == 0 or total < BATCH_SAMPLES):
                total += cfgs[members[size]].n_samples + cfgs[members[size]].warmup_samples
                size += 1
            batch, members = members[:size], members[size:]
            alone = _alone(
                [cfgs[i].n_samples + cfgs[i].warmup_samples for i in batch],
                len({cfgs[i].valve for i in batch} - {"linear"}),
            )
            for i in batch[:alone]:
                out[i] = simulate_loop(cfgs[i])
            if alone < len(batch):
                rest = batch[alone:]
                for i, rec in zip(rest, _batch([cfgs[i] for i in rest]), strict=True):
                    out[i] = rec
    return [r for r in out if r is not None]


def _alone(lengths: Sequence[int], sticky_models: int) -> int:
    """How many of the loops (``lengths``, longest first) to step one at a time, the rest
    side by side, for the least cost (``STEP_COST``)."""
    per_step = STEP_COST + STICKY_STEP_COST * sticky_models
    rest = float(sum(lengths))
    before = 0.0
    best, best_cost = len(lengths), rest
    for j, n in enumerate(lengths):
        cost = before + n * per_step + LOOP_SAMPLE_COST * rest
        if cost < best_cost:
            best, best_cost = j, cost
        before += n
        rest -= n
    return best


@dataclass
class _Friction:
    """A batch's sticky-valve parameters (an array per field of ``valves.FRICTION_FIELDS``,
    and what the steps read from them: ``half``, half the band a stem lags behind its input,
    and ``neg_S``), the nominal values and the generator of those whose friction drifts from
    stop to stop (``valves.DriftingFriction``)."""

    valve: str
    values: dict[str, FloatArray]
    nominal: dict[str, FloatArray]
    spread: FloatArray
    rngs: dict[int, random.Random]

    @classmethod
    def of(cls, valve: str, cfgs: Sequence[LoopConfig]) -> _Friction:
        if valve == "he":  # valves.HeValve from (S, J), as loop.make_valve builds it
            cols = {
                "fs": [(c.S + c.J) / 2.0 for c in cfgs],
                "fd": [(c.S - c.J) / 2.0 for c in cfgs],
            }
        elif valve == "backlash":
            cols = {"d": [c.S for c in cfgs]}
        else:
            cols = {"S": [c.S for c in cfgs], "J": [c.J for c in cfgs]}
        values = {k: np.array(v, dtype=np.float64) for k, v in cols.items()}
        rngs = {b: random.Random(c.seed + 1) for b, c in enumerate(cfgs) if c.friction_spread > 0.0}
        spread = np.array([c.friction_spread for c in cfgs])
        nominal = {k: v.copy() for k, v in values.items()}
        friction = cls(valve, values, nominal, spread, rngs)
        friction.derive(slice(None))
        return friction

    def derive(self, at: slice | int) -> None:
        """``half`` and ``neg_S`` of the loops ``at`` from their parameters (made, over every
        loop, by the first call). The models compute d·(S − J)/2 with d = ±1, the same value
        as d·half: a sign change and a halving are exact."""
        v = self.values
        if self.valve == "backlash":
            derived = {"half": v["d"][at] / 2.0}
        elif self.valve in ("kano", "choudhury"):
            derived = {"half": (v["S"][at] - v["J"][at]) / 2.0, "neg_S": -v["S"][at]}
        else:
            return
        for name, value in derived.items():
            if name in v:
                v[name][at] = value
            else:
                v[name] = np.array(value, dtype=np.float64)

    def narrow(self, n: int) -> None:
        """Keep the first ``n`` loops' parameters (views: a new friction still lands)."""
        self.values = {k: v[:n] for k, v in self.values.items()}

    def stopped(self, loops: BoolArray) -> None:
        """New friction for the drifting valves among ``loops`` (their stems just stopped)."""
        for b in np.flatnonzero(loops).tolist():
            rng = self.rngs.get(b)
            if rng is None:
                continue
            factor = math.exp(float(self.spread[b]) * rng.gauss(0.0, 1.0))
            for k, v in self.nominal.items():
                self.values[k][b] = float(v[b]) * factor
            self.derive(b)


def _clip(u: FloatArray) -> FloatArray:
    """``valves._clip``: 0 below 0, 100 above 100, else the value (NaN passes)."""
    return np.where(u < 0.0, 0.0, np.where(u > 100.0, 100.0, u))


class _Valves:
    """One sticky model's states over the loops of a batch that have it (``members``, their
    places in the batch, ascending); ``step`` is the model's ``step`` on each of them."""

    def __init__(self, valve: str, friction: _Friction, members: NDArray[np.intp]) -> None:
        self.valve = valve
        self.f = friction
        self.members = members
        size = members.size
        self.u_old = np.zeros(size)
        self.du_old = np.zeros(size)
        self.us = np.zeros(size)
        self.y = np.zeros(size)
        self.d = np.full(size, -1.0)
        # Kano starts moving, Choudhury stuck
        self.moving = np.full(size, valve == "kano")
        self.last = np.zeros(size)
        self.was_moving = np.zeros(size, dtype=bool)

    def narrow(self, alive: int) -> None:
        """Keep the members among the batch's first ``alive`` loops (the others have ended;
        the batch is ordered longest first, so they are a prefix of the members)."""
        n = int(np.searchsorted(self.members, alive))
        for name in ("members", "u_old", "du_old", "us", "y", "d", "moving", "last", "was_moving"):
            setattr(self, name, getattr(self, name)[:n])
        self.f.narrow(n)

    def step(self, k: int, u: FloatArray) -> FloatArray:
        """The stem positions for the members' clipped controller outputs ``u``."""
        y = self._first(u) if k == 0 else self._next(u)
        if self.f.rngs:  # valves.DriftingFriction: a stem that stops gets a new friction
            moving = (y != self.last) if k > 0 else np.zeros(y.size, dtype=bool)
            stops = self.was_moving & ~moving
            if stops.any():
                self.f.stopped(stops)
            self.was_moving, self.last = moving, y
        return y

    def _first(self, u: FloatArray) -> FloatArray:
        v = self.f.values
        self.u_old, self.y = u, u
        if self.valve == "kano":
            self.us = u + (v["S"] - v["J"]) / 2.0
        elif self.valve == "choudhury":
            self.us = u
        return u

    def _next(self, u: FloatArray) -> FloatArray:
        v = self.f.values
        if self.valve == "kano":
            du = u - self.u_old
            halt = (du * self.du_old <= 0.0) & self.moving
            self.us = np.where(halt, self.u_old, self.us)
            # the stem stops (halt, which only a moving stem does) or keeps still (held):
            # ``moving & ~halt`` is ``moving ^ halt``
            going = self.moving ^ halt
            gap = self.d * (u - self.us)
            back = gap < v["neg_S"]  # -d·(u - us) > S: the input went back through the band
            self.d = np.where(back & ~going, -self.d, self.d)
            # a held stem slips forward past J or back past S (never both: S, J >= 0)
            self.moving = going | back | (gap > v["J"])
            y = np.where(self.moving, u - self.d * v["half"], self.y)
            self.du_old, self.u_old = du, u
            self.y = _clip(y)
        elif self.valve == "he":
            fs, fd = v["fs"], v["fd"]
            ur = u - self.y
            self.y = np.where(np.abs(ur) > fs, _clip(u - np.where(ur > 0, fd, -fd)), self.y)
        elif self.valve == "choudhury":
            s = v["S"]
            du = u - self.u_old
            stuck = ~self.moving
            halt = ~stuck & (du * self.du_old <= 0.0)
            self.us = np.where(halt, self.u_old, self.us)
            stuck = (stuck | halt) & ~(np.abs(u - self.us) > s)
            direction = np.where(
                du != 0.0, np.where(du > 0, 1.0, -1.0), np.where(u >= self.us, 1.0, -1.0)
            )
            self.y = np.where(stuck, self.y, _clip(u - direction * v["half"]))
            self.moving = ~stuck
            self.du_old = np.where(du != 0.0, du, self.du_old)
            self.u_old = u
        else:  # backlash
            half = v["half"]
            x = self.y
            self.y = np.where(u - x > half, u - half, np.where(x - u > half, u + half, x))
        return self.y


def _column(values: Sequence[float]) -> FloatArray:
    return np.array(values, dtype=np.float64)


BLOCK = 1024
"""Samples simulated between two copies of the loops' signals into and out of the batch's
arrays: the batch holds its loops' inputs and outputs for this many samples only."""


@dataclass
class _Loops:
    """What stays fixed through a run, one entry per loop of a batch (``ClosedLoop``'s
    constants): ``head(n)`` keeps the first ``n`` loops when the others have ended."""

    lag2: BoolArray
    zero: FloatArray
    tau2: FloatArray
    sp0: FloatArray
    a_filter: FloatArray
    one_less: FloatArray
    kc: FloatArray
    ki: FloatArray
    op_min: FloatArray
    op_max: FloatArray
    u0: FloatArray
    a1: FloatArray
    b1: FloatArray
    a2: FloatArray
    b2: FloatArray
    reads: NDArray[np.int64]

    def head(self, n: int) -> _Loops:
        return _Loops(**{k: v[:n] for k, v in vars(self).items()})


def _constants(cfgs: Sequence[LoopConfig]) -> tuple[int, _Loops]:
    """The longest dead time in samples, and the constants of ``ClosedLoop.__init__`` and
    ``run`` for each loop, computed by the same Python expressions. A branch a loop never
    takes gets neutral constants: an integrator's x1 is 1.0·x1 + K·ts·u, a loop without a
    moving second lag keeps x2 by 1.0·x2 + 0.0·x1, an unfiltered PV is 0.0·PV' + 1.0·PV."""
    proc = [c.process for c in cfgs]
    ts = [c.sample_time_s for c in cfgs]
    fopdt = [p.kind == "fopdt" for p in proc]
    a1 = [math.exp(-t / p.tau_s) if f else 1.0 for p, t, f in zip(proc, ts, fopdt, strict=True)]
    b1 = [p.K * (1 - a) if f else p.K * t for p, t, f, a in zip(proc, ts, fopdt, a1, strict=True)]
    moves_x2 = [f and p.tau2_s > 0 for p, f in zip(proc, fopdt, strict=True)]
    a2 = [math.exp(-t / p.tau2_s) if m else 1.0 for p, t, m in zip(proc, ts, moves_x2, strict=True)]
    b2 = [1 - a if m else 0.0 for a, m in zip(a2, moves_x2, strict=True)]
    a_filter = _column(
        [math.exp(-c.sample_time_s / c.pv_filter_s) if c.pv_filter_s > 0 else 0.0 for c in cfgs]
    )
    delay = np.array([delay_samples(p, t) for p, t in zip(proc, ts, strict=True)])
    lead = int(delay.max())
    return lead, _Loops(
        lag2=np.array([p.tau2_s > 0 for p in proc]),
        zero=_column([p.zero_s for p in proc]),
        tau2=_column([p.tau2_s if p.tau2_s > 0 else 1.0 for p in proc]),
        sp0=_column([c.sp for c in cfgs]),
        a_filter=a_filter,
        one_less=1.0 - a_filter,
        kc=_column([c.controller.Kc for c in cfgs]),
        ki=_column([c.controller.Kc * c.sample_time_s / c.controller.Ti_s for c in cfgs]),
        op_min=_column([c.controller.op_min for c in cfgs]),
        op_max=_column([c.controller.op_max for c in cfgs]),
        u0=_column([c.u0 for c in cfgs]),
        a1=_column(a1),
        b1=_column(b1),
        a2=_column(a2),
        b2=_column(b2),
        # where each loop's process input is read in the stem's history (``_batch``)
        reads=(lead - delay) * len(cfgs) + np.arange(len(cfgs)),
    )


def _stretch_masks(cfgs: Sequence[LoopConfig]) -> dict[int, tuple[BoolArray, ...]]:
    """For each loop with manual or frozen-transmitter stretches, by its place in ``cfgs``:
    over its run, warm-up included, where it is in manual, where a segment of
    ``loop._run_stretches`` in manual starts after the first sample (the operator takes over
    the last OP), where its transmitter is frozen, and where a freeze starts (the reading
    then held)."""
    out: dict[int, tuple[BoolArray, ...]] = {}
    for b, c in enumerate(cfgs):
        if c.manual or c.frozen_pv:
            manual, frozen = stretch_samples(c, c.manual), stretch_samples(c, c.frozen_pv)
            starts = np.zeros_like(manual)
            starts[1:] = (manual[1:] != manual[:-1]) | (frozen[1:] != frozen[:-1])
            freezes = frozen.copy()
            freezes[1:] &= ~frozen[:-1]
            out[b] = (manual, manual & starts, frozen, freezes)
    return out


def _batch(cfgs: Sequence[LoopConfig]) -> list[LoopRecord]:
    """Simulate loops side by side, ``ClosedLoop.run``'s arithmetic
    (the constants of ``_constants``). The loops are taken longest first, and a loop that has
    ended leaves the batch, so no sample is simulated past a loop's end. The output limits
    clamp with ``np.maximum`` and ``np.minimum``, which differ from Python's ``max`` and
    ``min`` only in the sign of a zero equal to a limit; a valve whose output limits lie within
    0-100 % is not clipped again (the clip returns its input)."""
    order = sorted(range(len(cfgs)), key=lambda b: -(cfgs[b].n_samples + cfgs[b].warmup_samples))
    cfgs = [cfgs[b] for b in order]
    size = len(cfgs)
    inputs = [loop_inputs(c) for c in cfgs]
    lengths = [c.n_samples + c.warmup_samples for c in cfgs]
    lead, full = _constants(cfgs)
    within = bool(np.all(full.op_min >= 0.0) and np.all(full.op_max <= 100.0))
    sticky = []
    for valve in STICKY_MODELS:
        members = np.array([b for b, c in enumerate(cfgs) if c.valve == valve], dtype=np.intp)
        if members.size:
            friction = _Friction.of(valve, [cfgs[b] for b in members])
            sticky.append(_Valves(valve, friction, members))
    pv_rec = [np.empty(n) for n in lengths]
    op_rec = [np.empty(n) for n in lengths]
    mv_rec = [np.empty(n) for n in lengths]
    # the stem's history: ``lead`` rows before the block's first sample (u0 at the start, the
    # dead time's queue as ``ClosedLoop`` fills it), then the block's; a loop reads its
    # process input ``delay`` rows back, a loop without dead time this sample's row
    hist = np.empty((lead + BLOCK, size))
    hist[:lead] = full.u0
    flat = hist.reshape(-1)
    pv_blk = np.empty((BLOCK, size))
    op_blk = np.empty((BLOCK, size))
    drive = np.zeros((4, BLOCK, size))  # set point, load, output disturbance, noise
    stretches = _stretch_masks(cfgs)
    # in manual, where an operator takes over, frozen, where a transmitter freezes
    modes = np.zeros((4, BLOCK, size), dtype=bool)
    alive = size
    c = full
    x1 = np.zeros(size)
    x2 = np.zeros(size)
    integral = full.u0.copy()
    pv_f = np.zeros(size)
    pv_last = full.sp0.copy()  # a transmitter frozen from the start reads the set point
    u_last = full.u0.copy()
    frozen_at = np.zeros(size)
    with np.errstate(all="ignore"):  # a diverging loop overflows as Python's floats do
        for k0 in range(0, lengths[0], BLOCK):
            kb = min(BLOCK, lengths[0] - k0)
            starting = alive
            for b in range(starting):
                count = min(kb, lengths[b] - k0)
                for j, signal in enumerate(inputs[b][2:]):
                    drive[j, :count, b] = signal[k0 : k0 + count]
                if b in stretches:
                    for j, mask in enumerate(stretches[b]):
                        modes[j, :count, b] = mask[k0 : k0 + count]
            for j in range(kb):
                k = k0 + j
                if lengths[alive - 1] <= k:
                    while lengths[alive - 1] <= k:
                        alive -= 1
                    c = full.head(alive)
                    for v in sticky:
                        v.narrow(alive)
                    x1, x2, integral, pv_f = x1[:alive], x2[:alive], integral[:alive], pv_f[:alive]
                    pv_last, u_last = pv_last[:alive], u_last[:alive]
                    frozen_at = frozen_at[:alive]
                y = np.where(c.lag2, x2 + c.zero * (x1 - x2) / c.tau2, x1)
                pv = c.sp0 + y + drive[2, j, :alive] + drive[3, j, :alive]
                pv = c.a_filter * (pv if k == 0 else pv_f) + c.one_less * pv
                pv_f = pv
                if stretches:
                    manual, takes, frozen, freezes = modes[:, j, :alive]
                    frozen_at = np.where(freezes, pv_last, frozen_at)
                    pv = np.where(frozen, frozen_at, pv)
                    pv_last = pv
                    integral = np.where(takes, u_last, integral)
                e = drive[0, j, :alive] - pv
                push = c.kc * e
                u_unsat = integral + push
                u = np.minimum(np.maximum(u_unsat, c.op_min), c.op_max)
                # clamping anti-windup: integrate inside the limits (nothing clamped off) or
                # when the error pulls back from the limit (clamped off and push of opposite
                # signs); a difference of floats is 0 only if they are equal, and no product
                # of a clamped excess (>= 1e-16) and a push (>= 1e-16, or 0) underflows
                over = u_unsat - u
                windup = (over * push < 0) | (over == 0)
                if stretches:  # manual: OP holds, the integral with it
                    u = np.where(manual, np.minimum(np.maximum(integral, c.op_min), c.op_max), u)
                    windup &= ~manual
                    u_last = u
                integral = np.where(windup, integral + c.ki * e, integral)
                m = u if within else _clip(u)
                if sticky:
                    m = m.copy()
                    for v in sticky:
                        if v.members.size:
                            m[v.members] = v.step(k, m[v.members])
                hist[lead + j, :alive] = m
                u_del = flat.take(c.reads + j * size) - c.u0 + drive[1, j, :alive]
                x1 = c.a1 * x1 + c.b1 * u_del
                x2 = c.a2 * x2 + c.b2 * x1
                pv_blk[j, :alive] = pv
                op_blk[j, :alive] = u
            for b in range(starting):
                count = min(kb, lengths[b] - k0)
                pv_rec[b][k0 : k0 + count] = pv_blk[:count, b]
                op_rec[b][k0 : k0 + count] = op_blk[:count, b]
                mv_rec[b][k0 : k0 + count] = hist[lead : lead + count, b]
            hist[:lead] = hist[kb : kb + lead].copy()
    records: list[LoopRecord | None] = [None] * size
    for b, (cfg, inp) in enumerate(zip(cfgs, inputs, strict=True)):
        rng, t, sp = inp[0], inp[1], inp[2]
        records[order[b]] = loop_record(cfg, rng, t, sp, pv_rec[b], op_rec[b], mv_rec[b])
    return [r for r in records if r is not None]

"""The live plant: every loop of a scenario advanced one fixed step at a time.

Each loop is a ``ClosedLoop`` (the same model as the batch ``simulate_loop``) fed by
disturbances generated on line. ``Plant.step()`` advances simulated time by the scenario's
``sample_time_s`` and refreshes ``values``: one row per loop with SP and PV in engineering
units, OP and MV in % of travel and Mode (1 auto, 0 manual). The clock (``clock.py``) decides
how fast steps follow each other in wall-clock time.
"""

from __future__ import annotations

import math
from collections import deque
from datetime import datetime, timedelta

import numpy as np
from numpy.typing import NDArray

from plantcheck.simulator.faults import Retune
from plantcheck.simulator.loop import ClosedLoop
from plantcheck.simulator.scenario import SIGNALS, DisturbanceSpec, LoopSpec, Scenario


class OnlineDisturbance:
    """One ``DisturbanceSpec`` evaluated sample by sample (same components as the batch
    generator: sine, random walk, first-order filtered noise, fixed and random steps)."""

    def __init__(self, spec: DisturbanceSpec, ts: float, rng: np.random.Generator) -> None:
        self.spec = spec
        self.ts = ts
        self.rng = rng
        self.phase = float(rng.uniform(0, 2 * math.pi))
        self.walk = 0.0
        self.filtered = 0.0
        self.a = math.exp(-ts / spec.filtered_noise_tau_s)
        self.random_steps = 0.0
        self.upstream: LiveLoop | None = None
        """The loop whose cycle this disturbance carries (``from_loop``), set by the plant."""
        self.carried: deque[float] = deque(maxlen=max(1, round(spec.delay_s / ts) + 1))
        self.path = 0.0
        """The carried deviation after the path's lag."""
        self.path_a = math.exp(-ts / spec.lag_s) if spec.lag_s > 0 else 0.0

    def value(self, t: float) -> float:
        """Disturbance at simulated time ``t`` (s); call once per step, in order."""
        d = self.spec
        out = 0.0
        if d.sine_amplitude:
            out += d.sine_amplitude * math.sin(2 * math.pi * t / d.sine_period_s + self.phase)
        if d.random_walk_std:
            self.walk += float(self.rng.normal(0.0, d.random_walk_std * math.sqrt(self.ts)))
            out += self.walk
        if d.filtered_noise_std:
            w = self.rng.normal(0.0, d.filtered_noise_std * math.sqrt(1 - self.a * self.a))
            self.filtered = self.a * self.filtered + float(w)
            out += self.filtered
        if d.step_every_s and d.step_std and self.rng.uniform() < self.ts / d.step_every_s:
            self.random_steps += float(self.rng.normal(0.0, d.step_std))
        out += self.random_steps
        for t_step, size in d.steps:
            if t >= t_step:
                out += size
        if self.upstream is not None:
            self.carried.append(self.upstream.deviation)
            self.path += (1.0 - self.path_a) * (self.carried[0] - self.path)
            out += d.gain * self.path
        return out


class LiveLoop:
    """A scenario loop with its on-line disturbances, set-point schedule and manual periods."""

    def __init__(self, spec: LoopSpec, ts: float, seed: int) -> None:
        self.spec = spec
        self.ts = ts
        self.rng = np.random.default_rng(seed)
        self.loop = ClosedLoop(spec.to_config(ts, seed))
        self.disturbances = [OnlineDisturbance(d, ts, self.rng) for d in spec.disturbances]
        self.schedule = sorted(spec.sp_schedule)
        self.controller_schedule = sorted(spec.controller_schedule)
        self.deviation = 0.0
        """PV − SP after the latest step (% of span): what reaches the loops downstream."""

    def set_point(self, t: float) -> float:
        """Set point (% of span) at simulated time ``t`` from the schedule."""
        sp = self.spec.sp
        if not self.schedule:
            return sp
        tt = t % self.spec.sp_repeat_s if self.spec.sp_repeat_s else t
        for t_step, value in self.schedule:
            if tt >= t_step:
                sp = value
        return sp

    def step(self, t: float) -> tuple[float, float, float, float, float]:
        """Advance one step at simulated time ``t``: (SP, PV, OP, MV, Mode) as served."""
        load = out_d = 0.0
        for d in self.disturbances:
            if d.spec.where == "load":
                load += d.value(t)
            else:
                out_d += d.value(t)
        noise = float(self.rng.normal(0.0, self.spec.noise_std)) if self.spec.noise_std else 0.0
        while self.controller_schedule and self.controller_schedule[0][0] <= t:
            _, kc, ti = self.controller_schedule.pop(0)
            self.loop.set_controller(kc, ti)
        auto = not any(a <= t < b for a, b in self.spec.manual)
        self.loop.auto = auto
        sp = self.set_point(t)
        pv, op, mv = self.loop.step(sp, load, out_d, noise)
        self.deviation = pv - sp
        if self.spec.mv_noise_std:
            mv += float(self.rng.normal(0.0, self.spec.mv_noise_std))
        mv_served = mv if self.spec.expose_mv else math.nan
        s = self.spec
        return s.to_eng(sp), s.to_eng(pv), op, mv_served, 1.0 if auto else 0.0


class Plant:
    """All loops of a scenario on one simulated clock.

    ``values[i]`` holds loop i's (SP, PV, OP, MV, Mode) after the latest step; ``time`` is the
    simulated UTC time of that sample; ``steps`` counts the steps taken.
    """

    def __init__(self, scenario: Scenario, start: datetime) -> None:
        self.scenario = scenario
        self.ts = scenario.clock.sample_time_s
        seeds = np.random.SeedSequence(scenario.clock.seed).generate_state(len(scenario.loop))
        self.loops = [
            LiveLoop(spec, self.ts, int(s)) for spec, s in zip(scenario.loop, seeds, strict=True)
        ]
        self.index = {spec.id: i for i, spec in enumerate(scenario.loop)}
        for live in self.loops:
            for d in live.disturbances:
                if d.spec.from_loop:
                    d.upstream = self.loops[self.index[d.spec.from_loop]]
        self.start = start
        self.steps = 0
        self.values: NDArray[np.float64] = np.full((len(self.loops), len(SIGNALS)), np.nan)

    @property
    def t(self) -> float:
        """Simulated seconds since the start of the latest sample."""
        return max(self.steps - 1, 0) * self.ts

    @property
    def time(self) -> datetime:
        """Simulated UTC time of the latest sample."""
        return self.start + timedelta(seconds=self.t)

    def retune(self, cmd: Retune) -> None:
        """New PI settings for one loop from the next sample on (the admin ``tune``)."""
        self.loops[self.index[cmd.loop]].loop.set_controller(cmd.Kc, cmd.Ti_s)

    def step(self) -> None:
        """Advance every loop by one sample."""
        t = self.steps * self.ts
        for i, loop in enumerate(self.loops):
            self.values[i] = loop.step(t)
        self.steps += 1

"""Actuator faults between the controller output and the valve stem (methods.md §7).

A smart positioner drives the stem to the controller output. ``Actuator`` wraps the valve
friction model (``valves.py``) and adds the positioner and its faults, one sample at a time:

- ``calibration``: MV = bias + gain·(valve position): zero/span error of the positioner;
- ``hunting``: an under-damped positioner (overshoot after OP moves) that also cycles on its own;
- ``air_leakage``: the stem drifts toward the fail-safe position (0 %) at ``leak_rate`` %/s,
  which the positioner only partly recovers;
- ``rate_limit``: an undersized actuator: the stem moves at most ``rate`` %/s;
- the friction faults (stiction, deadband/backlash) come from the valve model itself.

All values in % of travel, times in seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from plantcheck.simulator.valves import Valve

ActuatorFault = Literal["none", "calibration", "hunting", "air_leakage", "rate_limit"]


@dataclass(frozen=True)
class ActuatorSpec:
    """Configuration of the positioner and its fault (see ``Actuator``)."""

    fault: ActuatorFault = "none"
    positioner_tau_s: float = 0.5
    bias: float = 0.0
    gain: float = 1.0
    hunting_amplitude: float = 0.0
    hunting_period_s: float = 5.0
    damping: float = 0.15
    leak_rate: float = 0.0
    rate: float = 1.0

    def build(self, valve: Valve, ts: float) -> Actuator:
        """A fresh actuator around ``valve`` for sample time ``ts`` (s)."""
        return Actuator(valve, ts, self)


@dataclass
class Actuator:
    """Positioner plus valve: ``step(op)`` returns the measured stem position MV (% travel)."""

    valve: Valve
    ts: float
    spec: ActuatorSpec
    _x: float | None = field(default=None, init=False, repr=False)
    _v: float = field(default=0.0, init=False, repr=False)
    _leak: float = field(default=0.0, init=False, repr=False)
    _t: float = field(default=0.0, init=False, repr=False)

    def step(self, op: float) -> float:
        target = self.valve.step(op)
        if self._x is None:
            self._x = target
        self._t += self.ts
        if self.spec.fault == "hunting":
            # under-damped second-order positioner, natural period = hunting period;
            # semi-implicit Euler with sub-steps small enough to stay stable
            wn = 2.0 * math.pi / self.spec.hunting_period_s
            n_sub = max(1, math.ceil(wn * self.ts / 0.05))
            h = self.ts / n_sub
            for _ in range(n_sub):
                acc = wn * wn * (target - self._x) - 2.0 * self.spec.damping * wn * self._v
                self._v += acc * h
                self._x += self._v * h
            x = self._x + self.spec.hunting_amplitude * math.sin(wn * self._t)
        else:
            a = (
                math.exp(-self.ts / self.spec.positioner_tau_s)
                if self.spec.positioner_tau_s > 0
                else 0.0
            )
            desired = a * self._x + (1.0 - a) * target
            if self.spec.fault == "rate_limit":
                step = max(
                    -self.spec.rate * self.ts, min(self.spec.rate * self.ts, desired - self._x)
                )
                desired = self._x + step
            self._x = desired
            x = self._x
            if self.spec.fault == "air_leakage":
                self._leak += self.spec.leak_rate * self.ts
                x -= self._leak
            elif self.spec.fault == "calibration":
                x = self.spec.bias + self.spec.gain * x
        return min(100.0, max(0.0, x))

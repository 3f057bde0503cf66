"""Step-wise control-valve models for closed-loop simulation.

Each model maps the controller output OP (% of travel) to the valve stem position MV
(% of travel), one sample at a time, so that it can sit inside a feedback loop.

- ``LinearValve``: MV = OP (healthy valve).
- ``KanoValve``: two-parameter (S, J) stick-slip model of Kano, Maruta, Kugemoto & Shimizu
  (2004, DYCOPS), logic as in BDSIM ``stiction.m`` (methods.md §5.3).
- ``HeValve``: semi-physical (f_s, f_d) model of He, Wang, Pottmann & Qin (2007), methods.md §5.4;
  S ~ f_s + f_d and J ~ f_s - f_d.
- ``ChoudhuryValve``: the data-driven (S, J) model of Choudhury, Thornhill & Shah (2005): a
  valve that stops sticks until the input has moved S from where it stuck, either way.
- ``BacklashValve``: pure deadband (backlash) of width d: no stickband, no slip.
- ``DriftingFriction``: any of the four whose friction changes from one stop to the next.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field
from typing import Protocol


class Valve(Protocol):
    """A valve: OP in, MV out, both in % of travel."""

    def step(self, op: float) -> float:
        """Advance one sample with controller output ``op`` and return the stem position."""
        ...


def _clip(u: float) -> float:
    return 0.0 if u < 0.0 else 100.0 if u > 100.0 else u


@dataclass
class LinearValve:
    """Healthy valve: the stem follows the controller output exactly."""

    def step(self, op: float) -> float:
        return _clip(op)


@dataclass
class KanoValve:
    """Kano et al. (2004) stiction model.

    Parameters
    ----------
    S:
        Deadband plus stickband, % of valve travel.
    J:
        Slip jump, % of valve travel.
    """

    S: float
    J: float
    _u_old: float | None = field(default=None, init=False, repr=False)
    _du_old: float = field(default=0.0, init=False, repr=False)
    _moving: bool = field(default=True, init=False, repr=False)
    _us: float = field(default=0.0, init=False, repr=False)
    _d: float = field(default=-1.0, init=False, repr=False)
    _y: float = field(default=0.0, init=False, repr=False)

    def step(self, op: float) -> float:
        u = _clip(op)
        if self._u_old is None:
            self._u_old = u
            self._us = u + (self.S - self.J) / 2.0
            self._y = u
            return u
        du = u - self._u_old
        if du * self._du_old <= 0.0 and self._moving:
            self._us = self._u_old
            self._moving = False
        if self._moving:
            self._y = u - self._d * (self.S - self.J) / 2.0
        elif -self._d * (u - self._us) > self.S:
            self._d = -self._d
            self._y = u - self._d * (self.S - self.J) / 2.0
            self._moving = True
        elif self._d * (u - self._us) > self.J:
            self._y = u - self._d * (self.S - self.J) / 2.0
            self._moving = True
        self._du_old = du
        self._u_old = u
        self._y = _clip(self._y)
        return self._y


@dataclass
class HeValve:
    """He et al. (2007) semi-physical stiction model.

    Parameters
    ----------
    fs:
        Static friction band, % of travel.
    fd:
        Kinetic friction band, % of travel (``fd <= fs``).
    """

    fs: float
    fd: float
    _x: float | None = field(default=None, init=False, repr=False)

    def step(self, op: float) -> float:
        u = _clip(op)
        if self._x is None:
            self._x = u
            return u
        ur = u - self._x
        if abs(ur) > self.fs:
            self._x = _clip(u - (self.fd if ur > 0 else -self.fd))
        return self._x


@dataclass
class ChoudhuryValve:
    """Choudhury, Thornhill & Shah (2005) two-parameter stiction model.

    Unlike Kano's, a valve that has stopped needs the input to move the full band ``S`` away
    from where it stuck in either direction before it slips by ``J`` (% of travel).
    """

    S: float
    J: float
    _u_old: float | None = field(default=None, init=False, repr=False)
    _du_old: float = field(default=0.0, init=False, repr=False)
    _stuck: bool = field(default=True, init=False, repr=False)
    _us: float = field(default=0.0, init=False, repr=False)
    _y: float = field(default=0.0, init=False, repr=False)

    def step(self, op: float) -> float:
        u = _clip(op)
        if self._u_old is None:
            self._u_old = self._us = self._y = u
            return u
        du = u - self._u_old
        if not self._stuck and du * self._du_old <= 0.0:
            self._stuck, self._us = True, self._u_old
        if self._stuck and abs(u - self._us) > self.S:
            self._stuck = False
        if not self._stuck:
            direction = 1.0 if u >= self._us else -1.0
            if du != 0.0:
                direction = 1.0 if du > 0 else -1.0
            self._y = _clip(u - direction * (self.S - self.J) / 2.0)
        self._du_old = du if du != 0.0 else self._du_old
        self._u_old = u
        return self._y


@dataclass
class BacklashValve:
    """Pure deadband of width ``d`` (% of travel): the stem follows the input at d/2 behind
    it and holds while the input reverses inside the band (backlash in the linkage)."""

    d: float
    _x: float | None = field(default=None, init=False, repr=False)

    def step(self, op: float) -> float:
        u = _clip(op)
        if self._x is None:
            self._x = u
        elif u - self._x > self.d / 2.0:
            self._x = u - self.d / 2.0
        elif self._x - u > self.d / 2.0:
            self._x = u + self.d / 2.0
        return self._x


FRICTION_FIELDS: dict[type, tuple[str, ...]] = {
    KanoValve: ("S", "J"),
    HeValve: ("fs", "fd"),
    ChoudhuryValve: ("S", "J"),
    BacklashValve: ("d",),
}
"""The band and jump fields of each sticky model, in % of travel."""


@dataclass
class DriftingFriction:
    """A sticky valve whose friction is not the same at every stop: packing wear, temperature,
    the stem's position and the process pressure move the bands from one stick to the next,
    so a real stick-slip cycle is less regular than the models' own. Each time the stem
    stops, every band and jump of the wrapped model is set to its nominal value ×
    exp(``spread`` · N(0, 1)), one factor for all (J stays at most S); drawn from ``seed``,
    so a run is reproducible."""

    valve: KanoValve | HeValve | ChoudhuryValve | BacklashValve
    spread: float
    seed: int = 0
    _nominal: dict[str, float] = field(init=False, repr=False)
    _rng: random.Random = field(init=False, repr=False)
    _last: float | None = field(default=None, init=False, repr=False)
    _moving: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        names = FRICTION_FIELDS[type(self.valve)]
        self._nominal = {k: float(getattr(self.valve, k)) for k in names}
        self._rng = random.Random(self.seed)

    def step(self, op: float) -> float:
        y = self.valve.step(op)
        moving = self._last is not None and y != self._last
        if self._moving and not moving:
            factor = math.exp(self.spread * self._rng.gauss(0.0, 1.0))
            for k, v in self._nominal.items():
                setattr(self.valve, k, v * factor)
        self._moving, self._last = moving, y
        return y

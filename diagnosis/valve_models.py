"""Data-driven valve stiction models (methods.md §5): OP -> MV, in % of valve travel.

Every model runs on a whole grid of parameter pairs in one pass over time: the state is a
vector with one entry per pair, and each time step updates all pairs at once. The single-pair
functions are the one-row case of the grid functions. Inputs are not clipped to 0–100 % unless
``clip=True`` (recorded OP is sometimes scaled or mean-removed).

- Stenman, Gustafsson & Forsman (2003): one parameter d (stick band).
- Choudhury, Thornhill & Shah (2005, CEP 13:641): (S, J), the clean implementation of
  methods §5.2 (state updated only when the valve moves).
- Kano, Maruta, Kugemoto & Shimizu (2004, DYCOPS): (S, J), logic verified in BDSIM stiction.m
  (methods §5.3). The model used for Hammerstein quantification.
- He, Wang, Pottmann & Qin (2007, IECR 46:4549): (f_s, f_d), S ≈ f_s + f_d, J ≈ f_s − f_d.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def _prep(u: ArrayLike, clip: bool) -> FloatArray:
    x = np.asarray(u, dtype=np.float64)
    return np.clip(x, 0.0, 100.0) if clip else x


def _pairs(p1: ArrayLike, p2: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Two parameter arrays broadcast to one pair per row."""
    a = np.atleast_1d(np.asarray(p1, dtype=np.float64))
    b = np.atleast_1d(np.asarray(p2, dtype=np.float64))
    a2, b2 = np.broadcast_arrays(a, b)
    return np.asarray(a2, dtype=np.float64), np.asarray(b2, dtype=np.float64)


def stenman_grid(u: ArrayLike, d: ArrayLike, clip: bool = False) -> FloatArray:
    """Stenman model for every stick band in ``d`` (% travel); returns (len(d), len(u))."""
    x = _prep(u, clip)
    dd = np.atleast_1d(np.asarray(d, dtype=np.float64))
    out = np.empty((dd.size, x.size))
    y = np.full(dd.size, x[0])
    for k in range(x.size):
        move = np.abs(x[k] - y) > dd
        y = np.where(move, x[k], y)
        out[:, k] = y
    return out


SCALAR_PAIRS = 6
"""Up to this many pairs a plain Python loop per pair beats the per-step numpy overhead."""


def _kano_one(x: list[float], s: float, j: float, stuck: float) -> list[float]:
    """Kano model for one pair, sample by sample (the BDSIM logic of methods §5.3), started
    stuck at input ``stuck`` (see kano_grid)."""
    half = (s - j) / 2.0
    moving, d, us, y = False, -1.0, stuck, x[0]
    out = [y]
    du_old = 0.0
    for k in range(1, len(x)):
        uk = x[k]
        du = uk - x[k - 1]
        if du * du_old <= 0.0 and moving:  # input stops or reverses: the valve sticks
            us, moving = x[k - 1], False
        if moving:
            y = uk - d * half
        elif -d * (uk - us) > s:  # breakaway after a reversal
            d, moving = -d, True
            y = uk - d * half
        elif d * (uk - us) > j:  # breakaway in the same direction
            moving = True
            y = uk - d * half
        out.append(y)
        du_old = du
    return out


def kano_grid(
    u: ArrayLike,
    S: ArrayLike,
    J: ArrayLike,
    clip: bool = False,
    stuck: ArrayLike | None = None,
) -> FloatArray:
    """Kano et al. (2004) model for every pair (S[i], J[i]); returns (n_pairs, len(u)).

    The valve starts stuck, last moved downwards (direction −1), at input ``stuck`` (per
    pair, % travel; default the first input u0): it breaks free when the input leaves
    [stuck − J, stuck + S]. The default is BDSIM's start (moving downwards, so it sticks at u0
    on the first step). In a stick-slip cycle that band sits wherever the last reversal put it,
    and from a band the input never leaves the model never moves; ``stuck = u0 − S + φ·(S + J)``,
    φ in [0, 1], spans every start the first sample allows (φ = S/(S + J) is BDSIM's). The
    position reads u0 until the valve first moves.
    """
    x = _prep(u, clip)
    s, j = _pairs(S, J)
    half = (s - j) / 2.0
    n_p = s.size
    start = x[0] if stuck is None else stuck
    us = np.array(np.broadcast_to(start, s.shape), dtype=np.float64)
    if n_p <= SCALAR_PAIRS:
        xs = x.tolist()
        return np.array(
            [_kano_one(xs, float(a), float(b), float(c)) for a, b, c in zip(s, j, us, strict=True)]
        )
    # time along the first axis, so each step writes one contiguous row; returned transposed
    out = np.empty((x.size, n_p))
    moving = np.zeros(n_p, dtype=bool)
    d = -np.ones(n_p)
    y = np.full(n_p, x[0])
    out[0] = y
    du_old = 0.0
    rel = np.empty(n_p)
    tmp = np.empty(n_p)
    rev = np.empty(n_p, dtype=bool)
    same = np.empty(n_p, dtype=bool)
    neg_s = -s
    for k in range(1, x.size):
        uk = x[k]
        du = uk - x[k - 1]
        if du * du_old <= 0.0:
            # input stops or reverses: every moving valve sticks where the input was
            np.copyto(us, x[k - 1], where=moving)
            moving[:] = False
        # A moving valve has moved on in its direction d since it broke away (d·rel > 0), so
        # the breakaway tests below leave it moving with its d: they need no mask.
        np.subtract(uk, us, out=rel)
        np.multiply(d, rel, out=tmp)
        np.less(tmp, neg_s, out=rev)  # -d·rel > S: breakaway after a reversal
        np.greater(tmp, j, out=same)  # d·rel > J: breakaway in the same direction
        np.negative(d, out=d, where=rev)
        moving |= rev
        moving |= same
        np.multiply(d, half, out=tmp)
        np.subtract(uk, tmp, out=tmp)
        np.copyto(y, tmp, where=moving)
        out[k] = y
        du_old = du
    return out.T


def kano(
    u: ArrayLike, S: float, J: float, clip: bool = False, stuck: float | None = None
) -> FloatArray:
    """Kano et al. (2004) model for one (S, J) pair (% travel); ``stuck`` as in
    :func:`kano_grid`."""
    return np.asarray(kano_grid(u, [S], [J], clip, None if stuck is None else [stuck])[0])


def choudhury_grid(u: ArrayLike, S: ArrayLike, J: ArrayLike, clip: bool = False) -> FloatArray:
    """Choudhury et al. (2005) model (methods §5.2 clean form) for every pair (S[i], J[i])."""
    x = _prep(u, clip)
    s, j = _pairs(S, J)
    half = (s - j) / 2.0
    n_p = s.size
    out = np.empty((n_p, x.size))
    y = np.full(n_p, x[0])
    stuck = np.ones(n_p, dtype=bool)
    x_ss = np.full(n_p, x[0])
    d_last = np.zeros(n_p)
    out[:, 0] = y
    for k in range(1, x.size):
        xk = x[k]
        v = np.sign(xk - x[k - 1])
        keep = ~stuck & (v == d_last)
        y = np.where(keep, xk - d_last * half, y)
        newly = ~stuck & ~keep
        x_ss = np.where(newly, x[k - 1], x_ss)
        stuck = stuck | newly
        dx = xk - x_ss
        sdx = np.sign(dx)
        fwd = stuck & (d_last != 0) & (sdx == d_last) & (np.abs(dx) > j)
        rev = stuck & ~fwd & ((d_last == 0) | (sdx == -d_last)) & (np.abs(dx) > s)
        d_last = np.where(rev, sdx, d_last)
        go = fwd | rev
        y = np.where(go, xk - d_last * half, y)
        stuck = stuck & ~go
        out[:, k] = y
    return out


def choudhury(u: ArrayLike, S: float, J: float, clip: bool = False) -> FloatArray:
    """Choudhury et al. (2005) model for one (S, J) pair (% travel)."""
    return np.asarray(choudhury_grid(u, [S], [J], clip)[0], dtype=np.float64)


def _he_one(x: list[float], fs: float, fd: float, y: float) -> list[float]:
    """He model for one pair from valve position ``y``, sample by sample (methods §5.4)."""
    out = []
    for xk in x:
        ur = xk - y
        if ur > fs:
            y = xk - fd
        elif ur < -fs:
            y = xk + fd
        out.append(y)
    return out


def he_grid(
    u: ArrayLike,
    fs: ArrayLike,
    fd: ArrayLike,
    clip: bool = False,
    x0: ArrayLike | None = None,
) -> FloatArray:
    """He et al. (2007) model for every pair (f_s[i], f_d[i]) (% travel; friction bands,
    f_d >= 0: a slipping valve lands f_d behind the input).

    ``x0`` is the valve position before the first sample, per pair (default: the first input).
    With f_s > f_d the model never forgets it: on a ramp the valve slips in steps of
    f_s − f_d from wherever it started, and in a cycle whether and when it breaks free at each
    reversal depends on where it sits in the band u ± f_s.
    """
    x = _prep(u, clip)
    a, b = _pairs(fs, fd)
    if np.any(b < 0):
        raise ValueError("f_d must be >= 0 (a friction band in % of travel, f_d <= f_s)")
    start = np.full(a.size, x[0]) if x0 is None else np.asarray(x0, dtype=np.float64)
    y = np.array(np.broadcast_to(start, a.shape), dtype=np.float64)
    if a.size <= SCALAR_PAIRS:
        xs = x.tolist()
        return np.array(
            [_he_one(xs, *pair) for pair in zip(a.tolist(), b.tolist(), y.tolist(), strict=True)]
        )
    # time along the first axis, so each step writes one contiguous row; returned transposed.
    # In place, no temporaries: the valve breaks free when |x − y| > f_s and lands f_d behind
    # the input (x − f_d upwards, x + f_d downwards).
    out = np.empty((x.size, a.size))
    ur, tmp = np.empty(a.size), np.empty(a.size)
    slip = np.empty(a.size, dtype=bool)
    for k in range(x.size):
        xk = x[k]
        np.subtract(xk, y, out=ur)
        np.abs(ur, out=tmp)
        np.greater(tmp, a, out=slip)
        np.copysign(b, ur, out=tmp)
        np.subtract(xk, tmp, out=tmp)
        np.copyto(y, tmp, where=slip)
        out[k] = y
    return out.T


def he(
    u: ArrayLike, fs: float, fd: float, clip: bool = False, x0: float | None = None
) -> FloatArray:
    """He et al. (2007) model for one (f_s, f_d) pair; ``x0`` as in :func:`he_grid`."""
    return np.asarray(he_grid(u, [fs], [fd], clip, None if x0 is None else [x0])[0])


def stenman(u: ArrayLike, d: float, clip: bool = False) -> FloatArray:
    """Stenman et al. (2003) model for one stick band d."""
    return np.asarray(stenman_grid(u, [d], clip)[0], dtype=np.float64)

"""Signal helpers shared by the diagnosis tests: ACF, zero crossings, half-cycles, filters.

All functions are pure and vectorised over numpy arrays. Sample indices are integers,
times are in seconds only where a sample time ``ts`` is passed explicitly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
ScalarT = TypeVar("ScalarT", bound=np.generic)
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]

_MAD_TO_SIGMA = 1.4826


def detrend(x: FloatArray) -> FloatArray:
    """Remove the least-squares straight line from ``x``."""
    n = x.size
    if n < 2:
        return x - x.mean() if n else x
    t, tt = centred_time(n)
    xc = x - mean(x)
    slope = float(t @ xc) / tt
    out = np.asarray(xc, dtype=np.float64)  # xc itself unless x was not float64
    out -= slope * t  # in place: out is this call's own
    return out


def centred_time(n: int) -> tuple[FloatArray, float]:
    """Sample indices 0 .. ``n`` − 1 less their mean (n − 1)/2, read-only, and their sum of
    squares. Kept for up to ``KEPT_TIME_AXIS`` samples: the chain detrends and fits lines on
    the same few lengths dozens of times per window."""
    return _kept_centred_time(n) if n <= KEPT_TIME_AXIS else _centred_time(n)


KEPT_TIME_AXIS = 8192
"""Longest time axis ``centred_time`` keeps (128 of them at most: 8 MB)."""


def _centred_time(n: int) -> tuple[FloatArray, float]:
    t = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)
    t.flags.writeable = False
    return t, float(t @ t)


_kept_centred_time = lru_cache(maxsize=128)(_centred_time)


@lru_cache(maxsize=64)
def fast_fft_length(n: int) -> int:
    """Smallest 2**a·3**b·5**c >= ``n``: a length pocketfft transforms fast
    (``scipy.fft.next_fast_len(n, real=True)``, without importing ``scipy.fft``)."""
    best = 1 << max(0, (n - 1).bit_length())
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            q = p35
            while q < n:
                q *= 2
            best = min(best, q)
            p35 *= 3
        p5 *= 5
    return best


@lru_cache(maxsize=32)
def hann(n: int) -> FloatArray:
    """``np.hanning(n)``, read-only and kept per length: the chain tapers a dozen segments of
    the same few lengths per window, and building the taper cost more than applying it."""
    w = np.hanning(n)
    w.flags.writeable = False
    return w


def hann_power(x: FloatArray, nfft: int | None = None) -> FloatArray:
    """Periodogram of mean-removed ``x`` through a Hann window (Welch 1967, one segment):
    |FFT|² at the ``nfft // 2 + 1`` frequencies ``np.fft.rfftfreq(nfft)`` (default
    ``nfft = len(x)``), in the squared units of ``x``."""
    power: FloatArray = np.abs(np.fft.rfft((x - mean(x)) * hann(x.size), nfft)) ** 2
    return power


@dataclass(frozen=True)
class SignalSpectrum:
    """A signal less its mean and its FFT zero-padded to ``nfft`` (at least twice its length,
    so that the autocorrelation below is the linear one): what ``fft_acf`` and the evidence's
    correlation times and shapes read. The evidence builds the detrended error's once where
    its correlation time (``shape_evidence``) and its correlation shapes
    (``correlation_evidence``) read the same samples, the analysed stretch being the whole
    window (an FFT pair, 50 µs of a 3,600-sample window)."""

    centred: FloatArray
    spectrum: NDArray[np.complex128]
    nfft: int

    @classmethod
    def of(cls, x: FloatArray) -> SignalSpectrum:
        """From the signal ``x`` (detrended first where a trend is not to count)."""
        centred = x - mean(x)
        nfft = fast_fft_length(2 * centred.size)
        return cls(centred, np.fft.rfft(centred, nfft), nfft)

    @cached_property
    def autocovariance(self) -> FloatArray:
        """Σ x(t)·x(t+k) at lags k = 0 .. nfft − 1 (those past the length are 0)."""
        s = self.spectrum
        return np.asarray(np.fft.irfft(s.real**2 + s.imag**2, self.nfft), dtype=np.float64)

    def acf(self, max_lag: int) -> FloatArray:
        """The normalised (biased) autocorrelation at lags 0 .. ``max_lag`` − 1, ``acf[0] = 1``;
        zeros for a constant signal."""
        cov = self.autocovariance[:max_lag]
        if cov[0] <= 0:
            return np.zeros(max_lag)
        return np.asarray(cov / cov[0], dtype=np.float64)


def fft_acf(x: FloatArray, max_lag: int | None = None) -> FloatArray:
    """Normalised (biased) autocorrelation of mean-removed ``x`` via FFT, ``acf[0] = 1``.

    Lags 0 .. ``max_lag`` - 1 (default: ``len(x) // 2``). Returns zeros for a constant signal.
    """
    n = x.size
    return SignalSpectrum.of(x).acf(n // 2 if max_lag is None else min(max_lag, n))


def fft_ccf(u: FloatArray, y: FloatArray, max_lag: int) -> tuple[IntArray, FloatArray]:
    """Normalised cross-correlation r_uy(τ) = Σ u_k y_{k+τ} / (N σ_u σ_y), τ ∈ [−max_lag, max_lag].

    (Horch 1999 convention: u = OP, y = PV.) Returns (lags, ccf).
    """
    n = u.size
    uc = u - mean(u)
    yc = y - mean(y)
    nfft = fast_fft_length(2 * n)
    cross = np.fft.irfft(np.conj(np.fft.rfft(uc, nfft)) * np.fft.rfft(yc, nfft), nfft)
    denom = n * std(uc) * std(yc)
    lags = np.arange(-max_lag, max_lag + 1)
    vals = cross[lags % nfft] / denom if denom > 0 else np.zeros(lags.size)
    return lags, np.asarray(vals, dtype=np.float64)


def mean(x: FloatArray) -> float:
    """``numpy.mean`` of a 1-D float64 array, the same value to the bit (its sum, pairwise as
    numpy sums, over its size) without the wrapper's dispatch and checks: half its 4 µs on a
    window-long signal, and the chain takes about a hundred means a window. Any other array
    goes to ``numpy.mean``."""
    x = np.asarray(x)
    if x.dtype != np.float64 or x.ndim != 1 or x.size == 0:
        return float(np.mean(x))
    return float(np.add.reduce(x) / x.size)


def std(x: FloatArray) -> float:
    """``numpy.std`` of a 1-D float64 array (ddof 0), the same value to the bit: the same
    steps as numpy's (the mean, the squared deviations in place, their sum over the size, the
    square root) in half its 11 µs on a window-long signal. Any other array goes to
    ``numpy.std``."""
    x = np.asarray(x)
    if x.dtype != np.float64 or x.ndim != 1 or x.size == 0:
        return float(np.std(x))
    d = x - np.add.reduce(x) / x.size
    np.multiply(d, d, out=d)
    return math.sqrt(np.add.reduce(d) / x.size)


def median(x: FloatArray) -> float:
    """Median of a 1-D array without NaN, as ``numpy.median`` gives it (the mean of the two
    middle values for an even size), through ``numpy.partition`` alone: ``numpy.median``'s
    own checks cost more than the partition on the short arrays the chain reads by the
    dozen per window. Two order statistics asked at once for an odd size too: numpy 2.4's
    partition at one index took 5-10 times longer than at two (3,599 samples: 85 µs against
    9 µs)."""
    n = x.size
    h = n // 2
    if n % 2:
        return float(np.partition(x, (h, h + 1))[h] if n > 1 else x[0])
    part = np.partition(x, (h - 1, h))
    return float((part[h - 1] + part[h]) / 2.0)


def percentile(x: FloatArray, q: float) -> float:
    """``numpy.percentile(x, q)`` of a 1-D array without NaN (its default, linear
    interpolation: Hyndman & Fan 1996's definition 7), the same value to the bit, through
    one ``numpy.partition`` at the order statistics it reads: ``numpy.percentile``'s own
    handling cost ten times the partition on the few hundred values the chain asks of it
    (0.12 ms of a window)."""
    n = x.size
    if n == 1:
        return float(x[0])
    virtual = (n - 1) * (q / 100.0)
    lo = min(max(math.floor(virtual), 0), n - 1)
    hi = min(lo + 1, n - 1)
    # numpy's own order statistics (the ends as well), so that even the sign of a zero agrees
    part = np.partition(x, sorted({-1, 0, lo, hi}))
    a, b = float(part[lo]), float(part[hi])
    gamma = virtual - lo
    # numpy's _lerp: from the nearer end, so that gamma 1 gives b exactly
    return b - (b - a) * (1.0 - gamma) if gamma >= 0.5 else a + (b - a) * gamma


def noise_sigma(x: FloatArray) -> float:
    """Robust standard deviation of the white measurement noise in ``x``.

    From the median absolute second difference (a second difference of white noise has
    variance 6σ²), insensitive to slow oscillations and trends.
    """
    if x.size < 4:
        return 0.0
    return sigma_from_second_differences(np.diff(x, 2))


def drawn_line_steps(x: FloatArray) -> BoolArray:
    """Per second-difference step k (samples k to k + 2): ``x`` runs there on one sloping
    straight line, its second difference zero to float rounding and its first not zero. No
    recorded measurement or controller output is that smooth; an interpolating export's
    segment between two stored values is (a value resting at a clamp is constant, not
    drawn). NaN is never on a line."""
    d = np.diff(x)
    with np.errstate(invalid="ignore"):
        return np.asarray(
            (np.abs(np.diff(d)) <= 1e-9 * np.maximum(1.0, np.abs(x[1:-1]))) & (d[1:] != 0.0),
            dtype=bool,
        )


def sigma_from_second_differences(d2: FloatArray) -> float:
    """``noise_sigma`` from second differences already taken (some of them, say where the
    signal moves): their median absolute deviation over √6, robust to a few large ones."""
    return float(_MAD_TO_SIGMA * median(np.abs(d2 - median(d2))) / np.sqrt(6.0))


def log_grid(start: float, stop: float, num: int) -> FloatArray:
    """``num`` points from ``start`` to ``stop`` (both > 0), evenly spaced in log: what
    ``np.geomspace`` returns, to rounding, in a tenth of its time (it is called a dozen times
    per identification and proposal, issue 48's 5-ms budget)."""
    if num == 1:
        return np.array([float(start)])
    return np.asarray(start * (stop / start) ** (np.arange(num) / (num - 1.0)), dtype=np.float64)


def round_significant(x: FloatArray, digits: int) -> list[float]:
    """The values rounded to ``digits`` significant digits, as a list for JSON: what
    ``[float(f"{v:.{digits}g}") for v in x]`` gives, vectorised (a plot's 100 points)."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore"):
        mag = np.floor(np.log10(np.abs(x)))
    k = np.where(np.isfinite(mag), digits - 1 - mag, 0.0)
    # integer powers of ten both ways, so that the scaling is exact for the common cases
    up = np.power(10.0, np.maximum(k, 0.0))
    down = np.power(10.0, np.maximum(-k, 0.0))
    return [float(v) for v in np.rint(x * up / down) * down / up]


def block_means(x: FloatArray, block: int) -> FloatArray:
    """Means of ``x`` over consecutive blocks of ``block`` samples (a tail shorter than a
    block is dropped)."""
    n = x.size // block * block
    return np.asarray(x[:n].reshape(-1, block).mean(axis=1), dtype=np.float64)


def moving_average(x: FloatArray, width: int) -> FloatArray:
    """Centred moving average over ``width`` samples (edges use the available samples)."""
    if width <= 1 or x.size == 0:
        return x
    n = x.size
    width = min(width, n)
    c = np.empty(n + 1)
    c[0] = 0.0
    np.cumsum(x, out=c[1:])
    half_lo = width // 2
    half_hi = width - half_lo
    out = np.empty(n)
    # a full window inside, the samples there are at the edges: one slice each rather than
    # a gather through clipped indices (the chain averages a dozen window-long signals)
    out[half_lo : n - half_hi + 1] = (c[width:] - c[: n + 1 - width]) / width
    k = np.arange(half_hi, width)
    out[:half_lo] = c[k] / k
    k = np.arange(n - width + 1, n - half_lo)
    out[n - half_hi + 1 :] = (c[n] - c[k]) / (n - k)
    return out


@lru_cache(maxsize=32)
def _growth(poles: tuple[float, ...], size: int) -> FloatArray:
    """a**-k for each pole a (rows) and k = 0 .. size - 1, correctly rounded (read-only:
    shared between calls, as the chain filters with the same few poles window after window)."""
    a = np.asarray(poles, dtype=np.float64)[:, None]
    grow = np.power(a, -np.arange(size, dtype=np.float64))
    grow.flags.writeable = False
    return grow


def first_order_recursions(
    x: FloatArray,
    poles: Sequence[float],
    gains: Sequence[float],
    out: FloatArray | None = None,
    offset: float = 0.0,
) -> FloatArray:
    """Rows y[k] = a·y[k-1] + gain·x[k] from rest (y[-1] = 0), plus ``offset``, one per pole
    0 < a < 1: what ``scipy.signal.lfilter([gain], [1, -a], x) + offset`` returns, to
    rounding, without importing ``scipy.signal`` (half a second: issue 29). Written into
    ``out`` (rows x samples) when given.

    Closed form over blocks: within a block y[k] = a**k·(a·y0 + gain·Σ_{j<=k} a**-j·x[j]),
    the block short enough that a**-k stays far from overflow (e**600). Temporaries are
    block-sized: window-sized ones cost fresh pages (page faults) on every call.
    """
    x = np.asarray(x, dtype=np.float64)
    a = np.asarray(poles, dtype=np.float64)[:, None]
    g = np.asarray(gains, dtype=np.float64)[:, None]
    block = max(1, int(600.0 / -np.log(float(a.min()))))
    grow = _growth(tuple(float(v) for v in a[:, 0]), min(block, x.size))
    y = np.empty((a.shape[0], x.size)) if out is None else out
    carry = np.zeros((a.shape[0], 1))
    for start in range(0, x.size, block):
        seg = x[start : start + block]
        gr = grow[:, : seg.size]
        part = np.cumsum(gr * seg, axis=1)
        part *= g
        part += a * carry
        part /= gr
        carry = part[:, -1:].copy()
        if offset:
            part += offset
        y[:, start : start + seg.size] = part
    return y


def first_order_recursion(x: FloatArray, a: float, gain: float = 1.0) -> FloatArray:
    """y[k] = a·y[k-1] + gain·x[k] from rest (y[-1] = 0), 0 <= a < 1
    (``first_order_recursions`` with one pole)."""
    x = np.asarray(x, dtype=np.float64)
    if a <= 0.0:
        return gain * x
    return np.asarray(first_order_recursions(x, (a,), (gain,))[0], dtype=np.float64)


def first_order_lags(x: FloatArray, poles: Sequence[float]) -> FloatArray:
    """Unit-gain first-order lags y[k] = a·y[k-1] + (1 - a)·x[k] started at rest at ``x[0]``
    (pole a = exp(-ts/τ); a = 0 passes ``x`` through), one row per pole."""
    x = np.asarray(x, dtype=np.float64)
    out = np.empty((len(poles), x.size))
    lagging = [i for i, a in enumerate(poles) if a > 0.0]
    for i, a in enumerate(poles):
        if a <= 0.0:
            out[i] = x
    if not lagging or x.size == 0:
        return out
    a_l = [poles[i] for i in lagging]
    gains = [1.0 - v for v in a_l]
    if lagging == list(range(lagging[0], lagging[-1] + 1)):
        rows = out[lagging[0] : lagging[-1] + 1]  # a view: written in place
        first_order_recursions(x - x[0], a_l, gains, rows, float(x[0]))
    else:
        out[lagging] = first_order_recursions(x - x[0], a_l, gains, offset=float(x[0]))
    return out


def first_order_lag(x: FloatArray, a: float) -> FloatArray:
    """Unit-gain first-order lag y[k] = a·y[k-1] + (1 - a)·x[k] started at rest at ``x[0]``
    (pole ``a`` = exp(-ts/τ))."""
    return np.asarray(first_order_lags(x, (a,))[0], dtype=np.float64)


def bandpass(x: FloatArray, ts: float, f_lo: float, f_hi: float) -> FloatArray:
    """Zero-phase band-pass by zeroing FFT bins outside [f_lo, f_hi] Hz (Wiener-type filter).

    Choudhury, Shah & Thornhill (2006) use this non-causal filter before ellipse fitting.
    """
    n = x.size
    spec = np.fft.rfft(x - mean(x))
    f = np.fft.rfftfreq(n, ts)
    spec[(f < f_lo) | (f > f_hi)] = 0.0
    return np.asarray(np.fft.irfft(spec, n), dtype=np.float64)


def hysteresis_sign(x: FloatArray, band: float) -> NDArray[np.int8]:
    """Sign of ``x`` that only changes when ``x`` leaves the band [−band, band].

    Samples inside the band keep the previous sign; leading in-band samples take the first
    decided sign. Returns +1/−1 (all +1 when ``x`` never leaves the band).
    """
    s0 = (x > band).view(np.int8) - (x < -band).view(np.int8)
    nz = np.flatnonzero(s0)
    if nz.size == 0:
        return np.ones(x.size, dtype=np.int8)
    # each sample takes the last decided sign up to it (by the count of decided samples so
    # far), the leading ones the first: int8 and a count rather than a running maximum of
    # positions, two-thirds of the time (the chain reads four signals' crossings a window)
    decided = np.cumsum(s0 != 0) - 1
    decided[: nz[0]] = 0
    return np.asarray(s0[nz][decided], dtype=np.int8)


def zero_crossings(x: FloatArray, band: float = 0.0) -> IntArray:
    """Indices where ``x`` crosses zero, confirmed by a hysteresis ``band``.

    A crossing is kept only when the signal goes from below −band to above +band (or back);
    its index is that of the last raw sign change before the confirmation, i.e. the sample
    where the new half-cycle starts.
    """
    if x.size < 2:
        return np.empty(0, dtype=np.intp)
    s = hysteresis_sign(x, band)
    conf = np.flatnonzero(np.diff(s)) + 1
    if conf.size == 0 or band <= 0:
        return conf.astype(np.intp)
    raw = np.flatnonzero(np.signbit(x[:-1]) != np.signbit(x[1:])) + 1
    pos = np.searchsorted(raw, conf, side="right") - 1
    starts = np.where(pos >= 0, raw[np.clip(pos, 0, None)], conf)
    return np.asarray(starts, dtype=np.intp)


def interpolated_zero_crossings(x: FloatArray) -> FloatArray:
    """Fractional sample positions where ``x`` changes sign (linear interpolation)."""
    if x.size < 2:
        return np.empty(0)
    k = np.flatnonzero(np.signbit(x[:-1]) != np.signbit(x[1:]))
    x0 = x[k]
    x1 = x[k + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(x1 != x0, x0 / (x0 - x1), 0.0)
    return np.asarray(k + frac, dtype=np.float64)


@dataclass(frozen=True)
class HalfCycles:
    """Half-cycles of a mean-removed signal, resampled to a common normalised time base.

    ``shapes`` (n_half × n_points) holds each half-cycle flipped to be positive and divided
    by its RMS; ``starts``/``stops`` are sample indices; ``iae`` is Σ|x|·ts per half-cycle
    (signal units × seconds); ``peak`` is max |x| per half-cycle.
    """

    shapes: FloatArray
    starts: IntArray
    stops: IntArray
    iae: FloatArray
    peak: FloatArray

    @property
    def count(self) -> int:
        """Number of half-cycles."""
        return int(self.starts.size)


def half_cycles(
    x: FloatArray,
    ts: float,
    band: float = 0.0,
    min_samples: int = 5,
    n_points: int = 32,
) -> HalfCycles:
    """Split mean-removed ``x`` into half-cycles between confirmed zero crossings.

    The first and last partial half-cycles are dropped, as are half-cycles shorter than
    ``min_samples``. Each kept half-cycle is linearly resampled to ``n_points`` points on
    normalised time [0, 1], both ends pinned to zero.
    """
    starts, stops = half_cycle_bounds(x, band, min_samples)
    n_half = starts.size
    if n_half == 0:
        return HalfCycles(np.empty((0, n_points)), starts, stops, np.empty(0), np.empty(0))
    ax = np.abs(x)
    # Resample every half-cycle at once: positions start + s*(len) for s in (0, 1).
    s = unit_grid(n_points)
    length = (stops - starts).astype(np.float64)
    pos = starts[:, None] + s[None, :] * length[:, None]
    # zero crossings lie inside the signal (0 < start < stop < size): only i0 + 1 can run
    # past its end, at a crossing on the last sample
    i0 = np.floor(pos).astype(np.intp)
    i1 = np.minimum(i0 + 1, x.size - 1)
    frac = pos - i0
    vals = x[i0] * (1 - frac) + x[i1] * frac
    sign = np.sign(x[starts + (stops - starts) // 2])
    sign[sign == 0] = 1.0
    vals = vals * sign[:, None]
    vals[:, 0] = 0.0
    vals[:, -1] = 0.0
    rms = np.sqrt(np.mean(vals**2, axis=1))
    rms[rms == 0] = 1.0
    shapes = vals / rms[:, None]
    # peak over the raw samples of each half-cycle (stop < x.size always holds)
    return HalfCycles(shapes, starts, stops, half_cycle_iae(ax, starts, stops, ts),
                      segment_max(ax, starts, stops))  # fmt: skip


@lru_cache(maxsize=8)
def unit_grid(n: int) -> FloatArray:
    """``np.linspace(0, 1, n)``, read-only and kept per ``n`` (the half-cycles' common time
    base, built twice a window)."""
    s = np.linspace(0.0, 1.0, n)
    s.flags.writeable = False
    return s


def sorted_unique(x: NDArray[ScalarT]) -> NDArray[ScalarT]:
    """``np.unique`` of an array already sorted ascending: the first of each run of equal
    values, without ``np.unique``'s sort and checks (the identification's dead-time grids and
    the controller-change search's split points, each window)."""
    if x.size < 2:
        return x.copy()
    return x[np.concatenate(([True], x[1:] != x[:-1]))]


def distinct_count(x: FloatArray) -> int:
    """``np.unique(x).size`` of a 1-D array: its distinct values, every NaN counted as one (as
    ``np.unique``'s ``equal_nan``). ``np.unique`` imports ``numpy.ma`` at its first call,
    6-17 ms of a one-record ``plantcheck diagnose`` (issue 46's 0.7 s start-up budget)."""
    s = np.sort(x)  # NaN sort last
    finite = s.size - int(np.count_nonzero(np.isnan(s)))
    return int(sorted_unique(s[:finite]).size) + int(finite < s.size)


def half_cycle_bounds(x: FloatArray, band: float, min_samples: int) -> tuple[IntArray, IntArray]:
    """First and past-the-last sample of each of ``half_cycles``'s half-cycles: where a
    caller needs no shapes, the resampling is left out (``hagglund_loads`` reads only the
    areas, the oscillation's amplitude only the peaks)."""
    zc = zero_crossings(x, band)
    if zc.size < 2:
        empty = np.empty(0, dtype=np.intp)
        return empty, empty
    starts, stops = zc[:-1], zc[1:]
    keep = (stops - starts) >= min_samples
    return starts[keep], stops[keep]


def half_cycle_iae(ax: FloatArray, starts: IntArray, stops: IntArray, ts: float) -> FloatArray:
    """Σ|x|·ts over each half-cycle (signal units × s), from ``ax`` = |x|."""
    csum = np.concatenate(([0.0], np.cumsum(ax)))
    return np.asarray((csum[stops] - csum[starts]) * ts, dtype=np.float64)


def _segment_reduce(op: np.ufunc, x: FloatArray, starts: IntArray, stops: IntArray) -> FloatArray:
    """``op`` over ``x[start:stop]`` of every (non-empty) segment, at once: ``reduceat`` over
    the interleaved (start, stop) pairs, read at the even positions (the odd ones, between
    segments, are dropped, so segments may overlap or leave gaps). A stop at ``x.size`` reads
    through a copy of ``x`` one sample longer (``reduceat`` takes no index past the end)."""
    if stops.size and int(stops.max()) >= x.size:
        x = np.append(x, x[-1])
    return np.asarray(op.reduceat(x, np.column_stack((starts, stops)).ravel())[::2], dtype=x.dtype)


def segment_max(x: FloatArray, starts: IntArray, stops: IntArray) -> FloatArray:
    """``max(x[start:stop])`` of every (non-empty) segment, at once (``_segment_reduce``)."""
    return _segment_reduce(np.maximum, x, starts, stops)


def segment_min(x: FloatArray, starts: IntArray, stops: IntArray) -> FloatArray:
    """``min(x[start:stop])`` of every (non-empty) segment, at once (``_segment_reduce``)."""
    return _segment_reduce(np.minimum, x, starts, stops)


def first_peaks(x: FloatArray, starts: IntArray, stops: IntArray) -> IntArray:
    """Index of the first maximum of ``x[start:stop]`` for every (non-empty) segment, at once.

    ``x`` finite; segments as for ``segment_max`` (half-cycles between zero crossings).
    """
    if starts.size == 0:
        return np.empty(0, dtype=np.intp)
    peak = segment_max(x, starts, stops)
    lengths = stops - starts
    offsets = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    idx = np.arange(int(lengths.sum())) + np.repeat(starts - offsets, lengths)
    hits = np.flatnonzero(x[idx] == np.repeat(peak, lengths))
    return np.asarray(idx[hits[np.searchsorted(hits, offsets)]], dtype=np.intp)


def fit_error_to_templates(shapes: FloatArray, templates: FloatArray) -> FloatArray:
    """Least-squares fit of every shape by every template with a free positive amplitude.

    ``shapes`` (n × m), ``templates`` (k × m). Returns the smallest mean-squared fitting error
    per shape over the templates (n,). The amplitude is A = <s, t>/<t, t>, clipped at 0.
    """
    norms = np.sqrt(np.sum(templates**2, axis=1))
    norms[norms == 0] = 1.0
    t_unit = templates / norms[:, None]
    proj = np.clip(shapes @ t_unit.T, 0.0, None)
    energy = np.sum(shapes**2, axis=1)
    best = np.max(proj, axis=1)
    return np.asarray((energy - best**2) / shapes.shape[1], dtype=np.float64)

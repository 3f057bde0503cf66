"""SciPy's IIR filters for the stiction quantification, imported when first used.

``scipy.signal`` takes half a second to import (it pulls in ``scipy.stats`` and
``scipy.interpolate``). Only the Hammerstein quantification needs general IIR filters; the
rest of the chain gets by with numpy (``signal_tools.first_order_recursion``, ``peaks``), so
a one-record CLI diagnosis of a loop without stiction never pays for the import (issue 29).

The quantification filters thousands of valve rows per window, so it calls SciPy's own
kernels where they are importable: ``lfilter``'s array-API dispatch costs ~20 µs a call, 40 %
of one row's simulation, and ``sosfilt`` copies its input first (same arguments, same result).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache
from typing import Any

import numpy as np

from plantcheck.diagnosis.signal_tools import FloatArray

IirFilter = Callable[[FloatArray, FloatArray, FloatArray, int], FloatArray]
"""(b, a, x, axis) -> y: ``scipy.signal.lfilter`` without initial conditions."""


@cache
def iir_filter() -> IirFilter:
    """``lfilter``'s kernel (or ``lfilter`` itself on a SciPy that moved it)."""
    try:
        from scipy.signal._sigtools import _linear_filter

        return _linear_filter  # type: ignore[no-any-return]
    except ImportError:  # pragma: no cover - a SciPy that moved its private kernel
        from scipy.signal import lfilter

        return lfilter  # type: ignore[no-any-return]


@cache
def _sosfilt_kernel() -> Any:
    try:
        from scipy.signal._sosfilt import _sosfilt

        return _sosfilt
    except ImportError:  # pragma: no cover - a SciPy that moved its private kernel
        return None


def filter_rows(sos: FloatArray, x: FloatArray) -> FloatArray:
    """Each row of ``x`` (a C-contiguous float64 temporary, overwritten) through the
    second-order sections ``sos`` from rest."""
    kernel = _sosfilt_kernel()
    if kernel is None:  # pragma: no cover
        from scipy.signal import sosfilt

        return np.asarray(sosfilt(sos, x, axis=1), dtype=np.float64)
    kernel(np.ascontiguousarray(sos), x, np.zeros((x.shape[0], sos.shape[0], 2)))
    return x


def sos_filter(sos: FloatArray, x: FloatArray) -> FloatArray:
    """``x`` through the second-order sections ``sos`` from rest (``scipy.signal.sosfilt``)."""
    from scipy.signal import sosfilt

    return np.asarray(sosfilt(sos, x), dtype=np.float64)


def butterworth_sos(order: int, edge: float, btype: str = "lowpass") -> FloatArray:
    """Butterworth filter as second-order sections; ``edge`` relative to Nyquist
    (``scipy.signal.butter``; Butterworth, 1930)."""
    from scipy.signal import butter

    return np.asarray(butter(order, edge, btype=btype, output="sos"), dtype=np.float64)


def notch_sos(frequency: float, q: float) -> FloatArray:
    """Second-order notch at ``frequency`` (cycles per sample) of quality ``q``
    (``scipy.signal.iirnotch``) as one second-order section."""
    from scipy.signal import iirnotch, tf2sos

    return np.asarray(tf2sos(*iirnotch(frequency, q, fs=1.0)), dtype=np.float64)

"""SciPy's IIR filters behind ``diagnosis/iir_kernels.py``: the kernels give what the public
functions give, and the standard chain imports no ``scipy.signal`` (half a second of a
one-record CLI diagnosis, issue 29) until the quantification needs it."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from scipy.signal import butter, iirnotch, lfilter, sosfilt, tf2sos

from plantcheck.diagnosis.iir_kernels import (
    butterworth_sos,
    filter_rows,
    iir_filter,
    notch_sos,
    sos_filter,
)


def test_kernels_equal_the_public_filters() -> None:
    rng = np.random.default_rng(5)
    x = rng.normal(size=(4, 700))
    b, a = np.array([0.2, 0.1]), np.array([1.0, -0.7])
    assert np.array_equal(iir_filter()(b, a, x[0], -1), lfilter(b, a, x[0]))
    high, notch = butterworth_sos(4, 0.05, btype="highpass"), notch_sos(0.02, 5.0)
    assert np.array_equal(high, butter(4, 0.05, btype="highpass", output="sos"))
    assert np.array_equal(notch, tf2sos(*iirnotch(0.02, 5.0, fs=1.0)))
    sos = np.vstack([high, notch])
    assert np.array_equal(filter_rows(sos, x.copy()), sosfilt(sos, x, axis=1))
    assert np.array_equal(sos_filter(sos, x[1]), sosfilt(sos, x[1]))


def test_the_standard_chain_imports_no_scipy_signal() -> None:
    code = (
        "import sys\n"
        "import numpy as np\n"
        "from plantcheck.diagnosis import diagnose\n"
        "rng = np.random.default_rng(0)\n"
        "pv = 50 + rng.normal(size=3600); op = 40 + rng.normal(size=3600)\n"
        "d = diagnose(pv, op, 1.0, quantify=False)\n"
        "print(sorted(m for m in sys.modules if m.startswith(('scipy.signal', 'scipy.stats'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"

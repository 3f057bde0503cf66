"""How fast an oscillation dies out: the decay ratio of its autocorrelation function
(Miao & Seborg 1999, "Automatic detection of excessively oscillatory feedback control loops",
IEEE CCA; methods.md §2.3).

A loop rings at its own frequency whenever noise or loads excite it; what makes the ringing a
tuning fault is how little it is damped. The ACF of a lightly damped loop's error decays slowly
(R near 1), a well damped loop's after one cycle (R near 0). Miao & Seborg call a loop
excessively oscillatory from R = 0.5.
"""

from __future__ import annotations

import numpy as np

from plantcheck.diagnosis.signal_tools import FloatArray, detrend, fft_acf, noise_sigma

EXCESSIVE_DECAY_RATIO = 0.5
"""R at and above which a loop is excessively oscillatory (Miao & Seborg 1999)."""


def acf_decay_ratio(x: FloatArray) -> float | None:
    """Miao & Seborg (1999) decay ratio R of the autocorrelation of ``x`` (dimensionless);
    None when the ACF (read to a third of the record) crosses zero fewer than four times.

    With τ1 the first minimum, τ2 the next maximum and τ3 the next minimum of the ACF ρ:
    a = ρ(τ2) − the line through (τ1, ρ(τ1)) and (τ3, ρ(τ3)) at τ2, b = the line through
    (0, 1) and (τ2, ρ(τ2)) at τ1 − ρ(τ1), and R = a/b. Each extremum is taken between two
    zero crossings of the ACF, so that measurement noise makes no extremum of its own. White
    measurement noise (σ from ``noise_sigma``) adds to ρ(0) only: the ACF is rescaled to the
    variance without it, or a noisy, lightly damped loop reads as well damped.
    """
    xd = detrend(np.asarray(x, dtype=np.float64))
    rho = fft_acf(xd, xd.size // 3)
    var = float(np.var(xd))
    var_noise = noise_sigma(xd) ** 2
    if var > var_noise > 0.0:
        rho = rho * (var / (var - var_noise))
        rho[0] = 1.0
    z = np.flatnonzero(np.diff(np.signbit(rho))) + 1
    if z.size < 4:
        return None
    t1 = int(z[0] + np.argmin(rho[z[0] : z[1]]))
    t2 = int(z[1] + np.argmax(rho[z[1] : z[2]]))
    t3 = int(z[2] + np.argmin(rho[z[2] : z[3]]))
    a = rho[t2] - (rho[t1] + (rho[t3] - rho[t1]) * (t2 - t1) / (t3 - t1))
    b = 1.0 + (rho[t2] - 1.0) * t1 / t2 - rho[t1]
    return float(a / b) if b > 0.0 else None

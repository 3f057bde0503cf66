"""Rebuild the Rice envelope table the diagnosis ships (``diagnosis/models/rice_envelope.npz``).

The mean of the Rice envelope needs the exponentially scaled Bessel functions I0e and I1e.
``scipy.special`` gives them, but importing it took 0.15 s of a 0.6-0.7 s ``plantcheck
diagnose`` (issue 46 asks 0.7 s): the diagnosis reads the table from its package instead, and
a test checks that the shipped table is the one this module computes, bit for bit.

    python -m plantcheck.service.rice_table [--out PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.cause_split import RICE_NU, RICE_TABLE


def rice_envelope_mean(nu: NDArray[np.float64]) -> NDArray[np.float64]:
    """Mean of the Rice envelope over σ at ν/σ = ``nu`` (Rice 1944):
    sqrt(π/2)·((1 + ν²/2)·I0e(ν²/4) + ν²/2·I1e(ν²/4)), increasing from sqrt(π/2)."""
    from scipy.special import i0e, i1e

    return np.asarray(
        np.sqrt(np.pi / 2) * ((1 + nu**2 / 2) * i0e(nu**2 / 4) + nu**2 / 2 * i1e(nu**2 / 4)),
        dtype=np.float64,
    )


def write_table(path: Path) -> None:
    """The table at ``RICE_NU`` into ``path`` (.npz, array ``mean``)."""
    np.savez_compressed(path, mean=rice_envelope_mean(RICE_NU))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=RICE_TABLE)
    args = ap.parse_args(argv)
    try:
        write_table(args.out)
    except OSError as exc:
        ap.exit(2, f"rice_table: cannot write --out {args.out}: {exc.strerror or exc}\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

"""One BLAS thread for every process that diagnoses, unless the environment says otherwise.

The chain multiplies matrices of a few thousand values, where OpenBLAS's extra threads only
spin on the other cores: a diagnosis worker burnt 27-30 ms of CPU per 1-h window with them and
17 ms without, at the same wall time (``benchmarks/service.py``, 2026-11-28), and one
``plantcheck diagnose`` of 3,600 samples 0.65-0.70 CPU-s against 0.47-0.59 (2026-11-30, two
cores). OpenBLAS reads its thread count once, when numpy is first imported, so the setting must
be in the environment before that: the command line sets it before any command imports numpy,
and spawned workers inherit it.
"""

from __future__ import annotations

import os

BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
"""What OpenBLAS, OpenMP and MKL read their thread counts from, at load."""


def one_blas_thread() -> None:
    """Ask for one BLAS thread in this process's environment, each variable the environment
    does not set already (a user's ``OPENBLAS_NUM_THREADS=4`` stands). The fits that want more
    threads (LightGBM, PyTorch) set their own counts (``cause_model_fit.FIT_THREADS``)."""
    for name in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")

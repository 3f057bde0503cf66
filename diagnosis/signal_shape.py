"""The window's shape read by a small convolutional network (issue 46): the control error, OP
and the set point resampled to ``SHAPE_SAMPLES`` points, each in units of its own spread, and
a few scale figures beside them. The chain's tests read what their authors knew to look for;
the network reads whatever the simulated corpus shows apart, and the learned decision weighs
both (``cause_model.decide``).

The network is four strided 1-D convolutions with ReLU (batch normalisation folded into their
weights at export), the mean and the maximum of the last one over time, and two dense layers
(the usual 1-D CNN for time-series classification: Wang, Yan & Oates 2017). It is fitted with
PyTorch by ``plantcheck model fit`` (``service.shape_model_fit``) and evaluated here in numpy,
the convolutions in float32 as PyTorch fitted them and the dense layers in float64.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.lib.stride_tricks import as_strided
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import mean, noise_sigma, std
from plantcheck.diagnosis.stiction_vote import is_integrating

FloatArray = NDArray[np.float64]
Float32Array = NDArray[np.float32]

SHAPE_SAMPLES = 512
"""Points each channel is resampled to: block means of a longer window, a linear
interpolation of a shorter one."""

SHAPE_CLIP = 8.0
"""Channel values are clipped to ± this many of their spread (a step of a nearly still loop
would otherwise dwarf the rest)."""

SCALARS: tuple[str, ...] = (
    "log_samples",
    "log_error_sd_noise",
    "log_op_sd",
    "log_op_sd_noise",
    "error_offset",
    "integrating",
    "op_at_max",
    "op_at_min",
)
"""The scale figures the network reads beside the channels (the channels have none)."""


@dataclass(frozen=True)
class ShapeInput:
    """One window prepared for the network: channels (3 × ``SHAPE_SAMPLES``: error, OP, set
    point) and ``SCALARS``."""

    channels: FloatArray
    scalars: FloatArray


def _resampled(x: FloatArray, points: int) -> FloatArray:
    n = x.size
    if n >= points:
        edges = np.linspace(0, n, points + 1).astype(np.int64)
        return np.asarray(np.add.reduceat(x, edges[:-1]) / np.diff(edges), dtype=np.float64)
    return np.interp(np.linspace(0, n - 1, points), np.arange(n), x)


def shape_input(
    pv: FloatArray,
    op: FloatArray,
    sp: FloatArray,
    loop_type: str,
    error_noise: float | None = None,
    op_noise: float | None = None,
) -> ShapeInput:
    """The network's input for one window (PV and SP in engineering units, OP in %, no NaN).
    ``error_noise``, ``op_noise``: ``noise_sigma`` of SP − PV and of OP where the caller has
    them (the window checks do), else computed here.

    The channels are stored as float16 in the fit's cache, so they pass through float16 here
    too: the network reads the same numbers in the fit and in a diagnosis."""
    e = sp - pv
    se = std(e) + 1e-12
    so = std(op) + 1e-12
    ne = max(noise_sigma(e) if error_noise is None else error_noise, 1e-9)
    no = max(noise_sigma(op) if op_noise is None else op_noise, 1e-9)
    chans = np.stack(
        [
            _resampled(e, SHAPE_SAMPLES) / se,
            _resampled(op - mean(op), SHAPE_SAMPLES) / so,
            _resampled(sp - mean(sp), SHAPE_SAMPLES) / se,
        ]
    )
    chans = np.clip(chans, -SHAPE_CLIP, SHAPE_CLIP).astype(np.float16).astype(np.float64)
    scalars = np.array(
        [
            np.log10(pv.size),
            np.log10(se / ne),
            np.log10(so),
            np.log10(so / no),
            mean(e) / se,
            1.0 if is_integrating(loop_type) else 0.0,
            float(np.mean(np.abs(op - op.max()) < 1e-9)),
            float(np.mean(np.abs(op - op.min()) < 1e-9)),
        ]
    )
    # float32, as the fit's cache keeps them
    return ShapeInput(chans, np.nan_to_num(scalars.astype(np.float32).astype(np.float64)))


@dataclass(frozen=True, eq=False)
class ShapeNet:
    """The network's weights: ``conv_w[i]`` (out × in × kernel, stride 2, zero padding of
    half the kernel) and ``conv_b[i]``, batch normalisation folded in; the dense layers
    ``dense_w``/``dense_b``; the scalars' mean, spread and range over the fit windows.

    A scalar outside the range the fit saw is read at its nearest end: a network extrapolates
    without bound, and one fitted without level loops (its ``integrating`` always 0, spread
    ~0) read a level loop's 1 as a million spreads off and called 81 % of them wrong
    (benchmarks/README.md, the families left out)."""

    conv_w: tuple[FloatArray, ...]
    conv_b: tuple[FloatArray, ...]
    dense_w: tuple[FloatArray, ...]
    dense_b: tuple[FloatArray, ...]
    scalar_mean: FloatArray
    scalar_sd: FloatArray
    scalar_min: FloatArray
    scalar_max: FloatArray
    conv_mats: tuple[tuple[Float32Array, Float32Array, int], ...] = field(init=False, repr=False)
    """Each convolution as the forward pass multiplies it: its weights as one (out × in·k)
    matrix and its bias as a column, in float32 (PyTorch fitted them in float32; the inputs
    are float16 numbers, exact in float32), and its kernel width. A float32 product takes
    half a float64 one's time: the decision 0.94-1.07 -> 0.70-0.83 ms a window (forty-sixth
    session, benchmarks/README.md); the log probabilities move by about 1e-6."""

    def __post_init__(self) -> None:
        mats = tuple(
            (
                np.ascontiguousarray(w.reshape(w.shape[0], -1), dtype=np.float32),
                np.asarray(b, dtype=np.float32)[:, None],
                int(w.shape[2]),
            )
            for w, b in zip(self.conv_w, self.conv_b, strict=True)
        )
        object.__setattr__(self, "conv_mats", mats)

    def to_arrays(self, prefix: str) -> dict[str, FloatArray]:
        """The arrays a model file keeps, named ``prefix`` + role + index."""
        out: dict[str, FloatArray] = {}
        for role, arrays in (("conv_w", self.conv_w), ("conv_b", self.conv_b),
                             ("dense_w", self.dense_w), ("dense_b", self.dense_b)):  # fmt: skip
            out.update({f"{prefix}{role}{i}": a for i, a in enumerate(arrays)})
        out[f"{prefix}scalar_mean"] = self.scalar_mean
        out[f"{prefix}scalar_sd"] = self.scalar_sd
        out[f"{prefix}scalar_min"] = self.scalar_min
        out[f"{prefix}scalar_max"] = self.scalar_max
        return out

    @classmethod
    def from_arrays(cls, z: Mapping[str, NDArray[np.generic]], prefix: str) -> ShapeNet:
        """The network ``to_arrays`` wrote under ``prefix``; ``z`` may be the open model file
        (only the network's arrays are read from it)."""

        def seq(role: str) -> tuple[FloatArray, ...]:
            out: list[FloatArray] = []
            while f"{prefix}{role}{len(out)}" in z:
                out.append(np.asarray(z[f"{prefix}{role}{len(out)}"], dtype=np.float64))
            return tuple(out)

        def one(role: str) -> FloatArray:
            return np.asarray(z[f"{prefix}{role}"], dtype=np.float64)

        return cls(seq("conv_w"), seq("conv_b"), seq("dense_w"), seq("dense_b"),
                   one("scalar_mean"), one("scalar_sd"), one("scalar_min"),
                   one("scalar_max"))  # fmt: skip


def shape_log_probabilities(net: ShapeNet, x: ShapeInput) -> FloatArray:
    """The network's log class probabilities for one window."""
    h: Float32Array = x.channels.astype(np.float32)
    for w, b, k in net.conv_mats:
        h = np.maximum(w @ _columns(h, k) + b, np.float32(0.0))
    z = np.concatenate(
        [
            h.mean(axis=1, dtype=np.float64),
            h.max(axis=1).astype(np.float64),
            (np.clip(x.scalars, net.scalar_min, net.scalar_max) - net.scalar_mean) / net.scalar_sd,
        ]
    )
    for i, (dense_w, dense_b) in enumerate(zip(net.dense_w, net.dense_b, strict=True)):
        z = dense_w @ z + dense_b
        if i < len(net.dense_w) - 1:
            z = np.maximum(z, 0.0)
    z = z - z.max()
    out: FloatArray = z - np.log(np.exp(z).sum())
    return out


def _columns(h: Float32Array, k: int) -> Float32Array:
    """(in × k, points): each output point's ``k`` inputs side by side, for a stride-2
    convolution of the channels ``h`` (in, length) with zero padding of k // 2 (as PyTorch's
    ``Conv1d(stride=2, padding=k // 2)``): one matrix product per layer. A strided view of the
    padded channels, copied once by the reshape: a third of an index gather's time."""
    in_ch, length = h.shape
    pad = k // 2
    points = (length + 2 * pad - k) // 2 + 1
    padded = np.zeros((in_ch, length + 2 * pad), dtype=np.float32)
    padded[:, pad : pad + length] = h
    along, across = padded.strides
    # tap j of point i reads padded[:, 2i + j]: never past the padded end (2(points − 1) + k
    # <= length + 2·pad by the definition of points)
    taps = as_strided(padded, (in_ch, k, points), (along, across, 2 * across), writeable=False)
    return np.asarray(taps.reshape(in_ch * k, points), dtype=np.float32)

"""Modbus register encoding and decoding: 16-bit registers ⇄ numbers, with byte and word order.

A register is a 16-bit unsigned integer. Multi-register values are split into words:

- ``word_order="big"``: the most significant word first (ABCD for float32, the Modbus
  convention); ``"little"``: least significant word first (CDAB);
- ``byte_order="big"``: each register's high byte first as sent on the wire; ``"little"``:
  the two bytes of every register swapped (BADC / DCBA devices). pymodbus'
  ``convert_from_registers`` handles word order only, hence this module.

Vectorised over numpy arrays: ``encode_float32`` turns any number of values into registers,
``decode`` turns a register block back into values of one data type.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

Order = Literal["big", "little"]
DataType = Literal["float32", "float64", "int16", "uint16", "int32", "uint32"]

WIDTH: dict[str, int] = {
    "float32": 2,
    "float64": 4,
    "int16": 1,
    "uint16": 1,
    "int32": 2,
    "uint32": 2,
}
"""Registers per value of each data type."""

_BIG_DTYPE = {
    "float32": ">f4",
    "float64": ">f8",
    "int16": ">i2",
    "uint16": ">u2",
    "int32": ">i4",
    "uint32": ">u4",
}


def _swap_bytes(regs: NDArray[np.uint16]) -> NDArray[np.uint16]:
    return ((regs & 0xFF) << 8 | (regs >> 8)).astype(np.uint16)


def encode(
    values: ArrayLike, dtype: DataType, word_order: Order = "big", byte_order: Order = "big"
) -> NDArray[np.uint16]:
    """Registers holding ``values`` as ``dtype`` (flat, ``WIDTH[dtype]`` registers each)."""
    arr = np.asarray(values).astype(_BIG_DTYPE[dtype])
    words = arr.view(">u2").reshape(arr.size, WIDTH[dtype])
    if word_order == "little":
        words = words[:, ::-1]
    regs = words.reshape(-1).astype(np.uint16)
    return _swap_bytes(regs) if byte_order == "little" else regs


def encode_float32(
    values: ArrayLike, word_order: Order = "big", byte_order: Order = "big"
) -> NDArray[np.uint16]:
    """Registers holding ``values`` as IEEE-754 float32 (two registers per value)."""
    return encode(values, "float32", word_order, byte_order)


def decode(
    registers: ArrayLike, dtype: DataType, word_order: Order = "big", byte_order: Order = "big"
) -> NDArray[np.float64]:
    """Values of ``dtype`` in a flat register block (length a multiple of ``WIDTH[dtype]``).

    Raises ``ValueError`` naming the problem when the block has the wrong length or holds a
    number outside 0–65535 (a malformed register).
    """
    regs = np.asarray(registers, dtype=np.int64)
    width = WIDTH[dtype]
    if regs.size % width:
        raise ValueError(f"{regs.size} registers do not split into {dtype} values of {width}")
    if regs.size and (regs.min() < 0 or regs.max() > 0xFFFF):
        raise ValueError("register value outside 0..65535")
    r16 = regs.astype(np.uint16)
    if byte_order == "little":
        r16 = _swap_bytes(r16)
    words = r16.reshape(-1, width)
    if word_order == "little":
        words = words[:, ::-1]
    big = np.ascontiguousarray(words).astype(">u2")
    return big.view(_BIG_DTYPE[dtype]).reshape(-1).astype(np.float64)

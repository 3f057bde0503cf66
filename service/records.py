"""Loop record files (contracts.md §1): CSV with a header, read into uniform numpy arrays.

- separator ``,``, ``;`` or tab, detected from the header line; column names case-insensitive;
- time from ``timestamp`` (ISO 8601, no zone = UTC; zones converted to UTC) or ``t`` (seconds;
  POSIX times in milliseconds, microseconds or nanoseconds are recognised by their size,
  converted and noted); without either the rows are taken as equally spaced at
  ``--sample-time`` (or 1 s, noted);
- a column name given twice is refused (which one holds the signal cannot be told);
- values beyond ±``MAX_ABS_VALUE`` are no measurement (an instrument's overflow code, a
  corrupt export): gaps, noted;
- ``pv``, ``op`` required for the diagnosis, ``sp``, ``mv``, ``mode`` optional;
- missing or non-numeric cells are gaps (NaN), never zeros;
- duplicate timestamps are merged (mean), unsorted rows are sorted, irregular spacing is
  resampled to the median spacing (linear interpolation; gaps longer than 3 samples stay NaN).

Errors that make a file unusable raise ``RecordError`` with a one-line message naming the
problem and the fix.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import warnings
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from plantcheck.diagnosis.signal_tools import median

FloatArray = NDArray[np.float64]

SIGNALS = ("sp", "pv", "op", "mv")
AUTO_MODES = frozenset({"1", "1.0", "auto", "cas", "automatic", "cascade"})
MAX_GAP_SAMPLES = 3


class RecordError(Exception):
    """A record file that cannot be used at all (exit status 2 in the CLI)."""


@dataclass
class LoopRecordFile:
    """A loop record on a uniform time grid.

    ``t`` in seconds from the first sample; signals in the record's units; ``auto`` is None
    when the file has no ``mode`` column.
    """

    t: FloatArray
    signals: dict[str, FloatArray]
    sample_time_s: float
    auto: NDArray[np.bool_] | None = None
    notes: list[str] = field(default_factory=list)
    start_epoch_s: float | None = None
    """POSIX time (s, UTC) of the first sample when the file has a ``timestamp`` column."""

    def get(self, name: str) -> FloatArray | None:
        """The named signal or None."""
        return self.signals.get(name)


def _detect_separator(header: str) -> str:
    counts = {sep: header.count(sep) for sep in (",", ";", "\t")}
    sep = max(counts, key=lambda s: counts[s])
    return sep if counts[sep] > 0 else ","


MAX_ABS_VALUE = 1e12
"""Largest magnitude taken as a measured value (any unit a loop uses stays far below)."""

EPOCH_UNITS = ((1e17, 1e9, "nanoseconds"), (1e14, 1e6, "microseconds"), (1e11, 1e3, "milliseconds"))
"""(smallest typical value, divisor, name): POSIX times in finer units than seconds. 1e11 s is
the year 5138, so a ``t`` that large is a finer unit, not seconds."""


def _to_float(cells: list[str]) -> FloatArray:
    """Parse cells as floats; anything non-numeric (or non-finite) becomes NaN."""
    try:
        fast = np.array(cells, dtype=np.float64)
    except ValueError:
        pass
    else:
        fast[~np.isfinite(fast)] = np.nan
        return fast
    out = np.full(len(cells), np.nan)
    for i, c in enumerate(cells):
        try:
            v = float(c)
        except ValueError:
            v = math.nan
            c2 = c.strip().replace(",", ".")
            if c2 and c2 != c:
                try:
                    v = float(c2)
                except ValueError:
                    v = math.nan
        out[i] = v if math.isfinite(v) else math.nan
    return out


def _parse_timestamps(cells: list[str], notes: list[str] | None = None) -> FloatArray:
    """ISO 8601 timestamps to POSIX seconds (no zone = UTC, other zones converted, noted);
    unparsable cells are NaN."""
    try:
        with warnings.catch_warnings():
            # numpy parses a "+01:00" with a deprecation warning: such cells take the slow path
            warnings.simplefilter("error")
            arr = np.array([c.strip().rstrip("Z") for c in cells], dtype="datetime64[us]")
        return np.asarray(arr.astype(np.int64) / 1e6, dtype=np.float64)
    except (ValueError, UserWarning, DeprecationWarning):
        pass
    out = np.full(len(cells), np.nan)
    zones: set[str] = set()
    for i, c in enumerate(cells):
        s = c.strip()
        if not s:
            continue
        try:
            dt = datetime.fromisoformat(s.replace("Z", "+00:00"))
        except ValueError:
            continue
        if dt.tzinfo is None:
            dt = dt.replace(tzinfo=UTC)
        zones.add(str(dt.utcoffset()))
        with contextlib.suppress(OverflowError, OSError, ValueError):
            out[i] = dt.timestamp()
    if notes is not None and zones - {"0:00:00"}:
        notes.append(
            f"timestamps carry {len(zones)} time zone offset(s) "
            f"({', '.join(sorted(zones))}): converted to UTC"
        )
    return out


def _epoch_seconds(t: FloatArray, notes: list[str]) -> FloatArray:
    """``t`` in seconds: POSIX times in ms, µs or ns recognised by their size and converted."""
    finite = t[np.isfinite(t)]
    if not finite.size:
        return t
    # numpy.median imports numpy.ma at its first call (6-17 ms of `diagnose`'s start)
    typical = median(np.abs(finite))
    for least, divisor, unit in EPOCH_UNITS:
        if typical >= least:
            if typical / divisor >= 1e11:
                return t  # beyond any unit: the time check refuses what is out of line
            notes.append(
                f"t read as POSIX time in {unit} (values near {typical:.3g}): converted to seconds"
            )
            return t / divisor
    return t


def _measured(values: FloatArray, name: str, notes: list[str]) -> FloatArray:
    """``values`` with magnitudes beyond ``MAX_ABS_VALUE`` as gaps (noted)."""
    wild = np.abs(np.nan_to_num(values, nan=0.0)) > MAX_ABS_VALUE
    if wild.any():
        notes.append(
            f"{int(wild.sum())} {name} values beyond ±{MAX_ABS_VALUE:.0e} taken as gaps (no "
            "instrument reads that: an overflow code or a corrupt export)"
        )
        values = np.where(wild, np.nan, values)
    return values


MAX_LINE_CHARS = 65_536
"""Longest line accepted: a record row holds a few numbers; a longer line is not a record."""
SNIFF_BYTES = 65_536
"""Bytes read first to tell text from binary data."""
MAX_GRID_PER_ROW = 20
"""A time axis that needs more grid points than this per row has a time far out of line."""


def _open_text(path: Path) -> io.TextIOWrapper:
    """The file as text with universal line ends (``\n``, ``\r\n`` or a lone ``\r``):
    UTF-8 (with or without a byte-order mark), else Latin-1; binary data is refused."""
    try:
        f = path.open("rb")
    except FileNotFoundError:
        raise RecordError(f"{path}: file not found; check the path") from None
    except IsADirectoryError:
        raise RecordError(f"{path}: is a directory; give a CSV record file") from None
    except OSError as exc:
        raise RecordError(f"{path}: cannot be read ({exc.strerror}); check permissions") from None
    head = f.read(SNIFF_BYTES)
    nul = head.find(b"\x00")
    if nul >= 0:
        f.close()
        raise RecordError(
            f"{path}: binary data (a NUL byte at byte {nul}), not CSV text; export the record "
            "as a CSV file with a header row"
        )
    f.seek(0)
    try:
        head.decode("utf-8-sig")
        encoding = "utf-8-sig"
    except UnicodeDecodeError as exc:
        # a multi-byte character cut at the end of the sniffed bytes is still UTF-8
        encoding = "utf-8-sig" if exc.start >= len(head) - 3 else "latin-1"
    return _as_text(f, encoding)


def _as_text(f: BinaryIO, encoding: str) -> io.TextIOWrapper:
    """``f`` decoded as a record is: bad bytes replaced, any line end read as one."""
    return io.TextIOWrapper(f, encoding=encoding, errors="replace", newline=None)


def _bounded_lines(f: io.TextIOWrapper, path: Path, before: int = 0) -> Iterator[str]:
    """The file's lines, refusing one longer than ``MAX_LINE_CHARS`` before it is in memory
    (``before``: lines of the file before ``f``'s first, for the line number named)."""
    k = before
    while True:
        line = f.readline(MAX_LINE_CHARS + 1)
        if not line:
            return
        k += 1
        if len(line) > MAX_LINE_CHARS:
            raise RecordError(
                f"{path}: line {k} is longer than {MAX_LINE_CHARS} characters; a record has "
                "one sample per line (check the file is the CSV export)"
            )
        yield line


SKIP_FROM_BYTES = 16 << 20
"""Files of at least this size whose rows exceed ``max_rows`` have their plain leading rows
counted, not parsed (``_plain_rows_to_skip``): a 10-million-row file (219 MB) took 17 s to
parse whole for the last 400,000 rows it keeps."""
TAIL_MARGIN_ROWS = 1000
"""Rows parsed beyond ``max_rows``: blank lines near the end cannot leave the tail short."""
_CHUNK_BYTES = 1 << 22


def _plain_rows_to_skip(
    path: Path, header_line: str, sep: str, encoding: str, keep: int
) -> tuple[int, int, int] | None:
    """(byte offset, lines before it, data rows before it) when the file's rows before that
    offset need no parsing to be counted, leaving the last ``keep`` rows and a margin after
    it: each ends in LF (CRLF too), none is blank or quoted or longer than ``MAX_LINE_CHARS``
    bytes, each holds the separator ``sep``, and the lines up to the header (``header_line``, as the
    text reader found it) have no lone CR either. None otherwise: the file is read whole."""
    with path.open("rb") as f:
        head = f.read(SNIFF_BYTES)
        start = 3 if head.startswith(b"\xef\xbb\xbf") else 0
        while True:
            end = head.find(b"\n", start)
            if end < 0:
                return None
            if head[start:end].strip():
                break
            start = end + 1
        before = head[: end + 1]
        if before.count(b"\r") != before.count(b"\r\n") or (
            head[start:end].decode(encoding, errors="replace").strip() != header_line.strip()
        ):
            return None
        header_lines = before.count(b"\n")
        f.seek(0)
        lines = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(_CHUNK_BYTES), b""))
        skip = lines - header_lines - keep - TAIL_MARGIN_ROWS
        if skip <= 0:
            return None
        pos, prev, done, carry = end + 1, end, 0, b""
        f.seek(pos)
        sep_byte = ord(sep)
        while done < skip:
            data = carry + f.read(_CHUNK_BYTES)
            cut = data.rfind(b"\n") + 1
            if cut == 0 or b'"' in data[:cut]:
                return None
            block, carry = np.frombuffer(data[:cut], np.uint8), data[cut:]
            nl = np.flatnonzero(block == 10)[: skip - done]
            starts = np.concatenate(([prev - pos + 1], nl[:-1] + 1))
            cr = np.flatnonzero(block[: nl[-1] + 1] == 13)
            seps = np.flatnonzero(block == sep_byte)
            plain = (
                (nl - starts <= MAX_LINE_CHARS).all()
                and (block[cr + 1] == 10).all()
                and (np.searchsorted(seps, nl) > np.searchsorted(seps, starts)).all()
            )
            if not plain:
                return None
            done += nl.size
            prev = pos + int(nl[-1])
            pos += cut
    return prev + 1, header_lines + skip, skip


def _reopen_at(path: Path, offset: int, encoding: str) -> io.TextIOWrapper:
    """The file as text from byte ``offset`` (a line's start), decoded as ``_open_text`` does."""
    f = path.open("rb")
    f.seek(offset)
    return _as_text(f, "utf-8" if encoding == "utf-8-sig" else encoding)


def _read_columns(
    path: Path, max_rows: int | None = None, skip_from_bytes: int | None = SKIP_FROM_BYTES
) -> tuple[list[str], list[list[str]], int]:
    """Header, the last ``max_rows`` data rows by column (all when None) and the row count.

    The file is streamed: memory holds at most ``max_rows`` rows whatever the file's size.
    A file of ``skip_from_bytes`` or more (None: never) has its plain leading rows counted
    and not parsed, when its last ``max_rows`` are all it keeps.
    """
    with contextlib.ExitStack() as stack:
        f = stack.enter_context(_open_text(path))
        lines = _bounded_lines(f, path)
        header_line = ""
        for line in lines:
            if line.strip():
                header_line = line
                break
        if not header_line:
            raise RecordError(f"{path}: file is empty; a header row and data rows are needed")
        sep = _detect_separator(header_line)
        header = [h.strip().lower() for h in next(csv.reader([header_line], delimiter=sep))]
        ncol = len(header)
        skipped = None
        if (
            max_rows is not None
            and skip_from_bytes is not None
            and path.stat().st_size >= skip_from_bytes
        ):
            skipped = _plain_rows_to_skip(path, header_line, sep, f.encoding, max_rows)
        total = 0
        if skipped is not None:
            offset, before, total = skipped
            tail = stack.enter_context(_reopen_at(path, offset, f.encoding))
            lines = _bounded_lines(tail, path, before)
        rows: deque[list[str]] = deque(maxlen=max_rows)
        for row in csv.reader(lines, delimiter=sep):
            if not row or (len(row) == 1 and not row[0].strip()):
                continue
            total += 1
            rows.append(row[:ncol] if len(row) >= ncol else row + [""] * (ncol - len(row)))
    if skipped is not None and len(rows) < (max_rows or 0):
        # the margin's rows were blank: the rows to keep reach into the counted ones
        return _read_columns(path, max_rows, None)
    columns = [list(c) for c in zip(*rows, strict=True)] if rows else [[] for _ in header]
    return header, columns, total


def read_record(
    path: str | Path, sample_time_s: float | None = None, max_rows: int | None = None
) -> LoopRecordFile:
    """Read and regularise a loop record file (contracts.md §1).

    ``max_rows`` keeps only the file's last rows (memory bounded whatever its size; noted).
    Raises ``RecordError`` when the file is missing, empty, binary, has a line longer than
    ``MAX_LINE_CHARS``, no header, no data rows, or a time far out of line.
    Signal columns are optional here; callers check what they need (``require``).
    """
    path = Path(path)
    header, columns, total = _read_columns(path, max_rows)
    notes: list[str] = []
    if max_rows is not None and total > max_rows:
        notes.append(f"record has {total} rows: read the last {max_rows}")
    if not any(h in ("pv", "op", "sp", "mv", "t", "timestamp", "mode") for h in header):
        raise RecordError(
            f"{path}: no known column in the header {header[:6]}; expected a header row with "
            "pv, op (and sp, mv, mode, timestamp or t)"
        )
    n = len(columns[0]) if columns else 0
    if n == 0:
        raise RecordError(f"{path}: header only, no data rows; record at least a few samples")
    if sample_time_s is not None and not (sample_time_s > 0 and math.isfinite(sample_time_s)):
        raise RecordError(
            f"--sample-time must be a positive number of seconds, not {sample_time_s}"
        )
    known = ("pv", "op", "sp", "mv", "t", "timestamp", "mode")
    twice = [h for h in known if header.count(h) > 1]
    if twice:
        where = [i + 1 for i, h in enumerate(header) if h == twice[0]]
        raise RecordError(
            f"{path}: column {twice[0]!r} appears {len(where)} times in the header (columns "
            f"{', '.join(map(str, where))}); keep the one that holds the signal and rename or "
            "delete the others"
        )
    col = {h: columns[i] for i, h in enumerate(header)}
    if "timestamp" in col:
        t = _parse_timestamps(col["timestamp"], notes)
        time_name = "timestamp"
    elif "t" in col:
        t = _epoch_seconds(_to_float(col["t"]), notes)
        time_name = "t"
    else:
        t = np.arange(n, dtype=np.float64) * (sample_time_s or 1.0)
        time_name = ""
        notes.append(
            f"no timestamp or t column: rows taken as equally spaced at {sample_time_s or 1.0:g} s"
        )
    signals = {
        name: _measured(_to_float(col[name]), name, notes) for name in SIGNALS if name in col
    }
    mode = None
    if "mode" in col:
        mode = np.array([c.strip().lower() in AUTO_MODES for c in col["mode"]], dtype=bool)
    bad_t = ~np.isfinite(t)
    if bad_t.all():
        raise RecordError(
            f"{path}: column {time_name!r} has no valid time value; use ISO 8601 timestamps "
            "or seconds"
        )
    if bad_t.any():
        notes.append(f"{int(bad_t.sum())} rows with an unreadable {time_name!r} dropped")
        keep = ~bad_t
        t = t[keep]
        signals = {k: v[keep] for k, v in signals.items()}
        mode = mode[keep] if mode is not None else None
    rec = _regularise(t, signals, mode, sample_time_s, notes, path, time_name == "timestamp")
    if time_name == "timestamp":
        rec = replace(rec, start_epoch_s=float(t.min()))
    return rec


def _regularise(
    t: FloatArray,
    signals: dict[str, FloatArray],
    mode: NDArray[np.bool_] | None,
    sample_time_s: float | None,
    notes: list[str],
    path: Path,
    epoch: bool,
) -> LoopRecordFile:
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(t.size)):
        notes.append("rows were not in time order: sorted")
        t = t[order]
        signals = {k: v[order] for k, v in signals.items()}
        mode = mode[order] if mode is not None else None
    uniq, inverse, counts = np.unique(t, return_inverse=True, return_counts=True)
    if uniq.size < t.size:
        notes.append(f"{t.size - uniq.size} duplicate timestamps merged (mean of the values)")
        merged = {}
        for k, v in signals.items():
            ok = np.isfinite(v)
            s = np.bincount(inverse, weights=np.where(ok, v, 0.0), minlength=uniq.size)
            c = np.bincount(inverse, weights=ok.astype(np.float64), minlength=uniq.size)
            with np.errstate(invalid="ignore", divide="ignore"):
                merged[k] = np.where(c > 0, s / np.where(c > 0, c, 1.0), np.nan)
        signals = merged
        if mode is not None:
            mode = (
                np.bincount(inverse, weights=mode.astype(np.float64), minlength=uniq.size) >= counts
            )
        t = uniq
    if t.size < 2:
        ts = sample_time_s or 1.0
        return LoopRecordFile(t - t[0], signals, ts, mode, notes)
    dt = np.diff(t)
    ts = float(sample_time_s) if sample_time_s else median(dt)
    regular = np.allclose(dt, ts, rtol=0.01, atol=1e-9)
    if regular:
        return LoopRecordFile(t - t[0], signals, ts, mode, notes)
    points = (t[-1] - t[0]) / ts + 1
    if points > MAX_GRID_PER_ROW * t.size:
        # one wrong time (year 9999, t = 1e308) would make the uniform grid exhaust memory
        i = int(np.argmax(dt))
        raise RecordError(
            f"{path}: the time jumps from {_time_text(t[i], epoch)} to "
            f"{_time_text(t[i + 1], epoch)} between two rows: {points:.3g} samples at "
            f"{ts:g} s for {t.size} rows; fix or delete the rows with a wrong time"
        )
    grid = t[0] + np.arange(math.floor((t[-1] - t[0]) / ts + 1e-9) + 1) * ts
    notes.append(f"irregular sample spacing: resampled to {ts:g} s ({grid.size} samples)")
    out: dict[str, FloatArray] = {}
    # position of each grid point between the original samples
    right = np.clip(np.searchsorted(t, grid, side="left"), 1, t.size - 1)
    left = right - 1
    gap = (t[right] - t[left]) > (MAX_GAP_SAMPLES + 1) * ts
    exact = np.isclose(t[np.clip(right, 0, t.size - 1)], grid)
    for k, v in signals.items():
        ok = np.isfinite(v)
        if ok.sum() < 2:
            out[k] = np.full(grid.size, np.nan)
            continue
        g = np.interp(grid, t[ok], v[ok])
        bad = (gap & ~exact) | ~(ok[left] | exact) | ~(ok[right] | ~exact)
        g[bad & ~exact] = np.nan
        out[k] = g
    mode_g = None
    if mode is not None:
        mode_g = mode[np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.size - 1)]
    return LoopRecordFile(grid - grid[0], out, ts, mode_g, notes)


def _time_text(t: float, epoch: bool) -> str:
    """A time as the file wrote it: ISO 8601 for a timestamp column, seconds for ``t``."""
    if epoch:
        with contextlib.suppress(ValueError, OverflowError, OSError):
            return datetime.fromtimestamp(t, UTC).isoformat().replace("+00:00", "Z")
    return f"{t:g} s"


def require(record: LoopRecordFile, path: str | Path, names: tuple[str, ...]) -> None:
    """Raise ``RecordError`` when a required column is missing from the record."""
    missing = [n for n in names if n not in record.signals]
    if missing:
        raise RecordError(
            f"{path}: no {', '.join(missing)} column; the header must name "
            f"{' and '.join(names)} (case-insensitive)"
        )

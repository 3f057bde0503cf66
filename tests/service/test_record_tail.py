"""A long record's leading rows counted, not parsed (``records._plain_rows_to_skip``): the
rows kept, the row count and every error are those of reading the file whole, plain or not."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from plantcheck.service.records import (
    MAX_LINE_CHARS,
    TAIL_MARGIN_ROWS,
    RecordError,
    _plain_rows_to_skip,
    _read_columns,
)

KEEP = 500
ROWS = KEEP + TAIL_MARGIN_ROWS + 2500


def _rows(n: int = ROWS, sep: str = ",", end: str = "\n") -> str:
    return "".join(f"{k}{sep}{50 + k % 7}{sep}{40 + k % 5}{end}" for k in range(n))


def _write(tmp: Path, text: str, encoding: str = "utf-8") -> Path:
    path = tmp / "record.csv"
    path.write_bytes(text.encode(encoding))
    return path


PLAIN: dict[str, Callable[[], str]] = {
    "comma": lambda: "t,pv,op\n" + _rows(),
    "crlf": lambda: "t,pv,op\r\n" + _rows(end="\r\n"),
    "semicolon": lambda: "t;pv;op\n" + _rows(sep=";"),
    "bom and blank lines first": lambda: "\ufeff\n  \r\nt,pv,op\n" + _rows(),
    "no final line end": lambda: "t,pv,op\n" + _rows()[:-1],
    "blank lines near the end": lambda: (
        "t,pv,op\n" + _rows() + "\n" * (TAIL_MARGIN_ROWS + 200) + _rows(100)
    ),
    "a short row": lambda: "t,pv,op\n1,2\n" + _rows(),
}
"""Files whose leading rows can be counted (the blank lines near the end leave the rows after
them short of ``KEEP``: that file is then read whole)."""

NOT_PLAIN: dict[str, Callable[[], str]] = {
    "a blank line": lambda: "t,pv,op\n" + _rows(100) + "\n" + _rows(),
    "a quoted cell": lambda: 't,pv,op\n1,"2",3\n' + _rows(),
    "a lone CR": lambda: "t,pv,op\n1,2,3\r" + _rows(),
    "a row without separator": lambda: "t,pv,op\n17\n" + _rows(),
}
"""Files read whole: the same rows and count either way."""


@pytest.mark.parametrize("case", [*PLAIN, *NOT_PLAIN])
def test_the_rows_kept_and_counted_are_those_of_the_whole_file(case: str, tmp_path: Path) -> None:
    path = _write(tmp_path, {**PLAIN, **NOT_PLAIN}[case]())
    whole = _read_columns(path, KEEP, None)
    assert _read_columns(path, KEEP, 0) == whole
    assert whole[2] >= ROWS and len(whole[1][0]) == KEEP
    sep = ";" if case == "semicolon" else ","
    counted = _plain_rows_to_skip(path, sep.join(("t", "pv", "op")), sep, "utf-8-sig", KEEP)
    assert (counted is not None) == (case in PLAIN), counted


def test_a_latin1_blank_header_lookalike_is_read_whole(tmp_path: Path) -> None:
    """A line of a no-break space (Latin-1 0xA0) before the header is blank to the text
    reader, not to a byte reader: the files' headers differ, so nothing is counted."""
    path = _write(tmp_path, "\xa0\nt,pv,op\n" + _rows(), encoding="latin-1")
    assert _read_columns(path, KEEP, 0) == _read_columns(path, KEEP, None)
    assert _plain_rows_to_skip(path, "t,pv,op", ",", "latin-1", KEEP) is None


def test_a_line_too_long_among_the_leading_rows_is_named_alike(tmp_path: Path) -> None:
    path = _write(tmp_path, "t,pv,op\n" + _rows(10) + "1," * MAX_LINE_CHARS + "\n" + _rows())
    with pytest.raises(RecordError) as whole:
        _read_columns(path, KEEP, None)
    with pytest.raises(RecordError) as counted:
        _read_columns(path, KEEP, 0)
    assert str(counted.value) == str(whole.value)
    assert "line 12 is longer" in str(whole.value)


def test_an_error_in_the_rows_read_names_its_line_in_the_file(tmp_path: Path) -> None:
    """Line numbers count the rows that were counted and not parsed."""
    path = _write(tmp_path, "t,pv,op\n" + _rows() + "1," * MAX_LINE_CHARS + "\n" + _rows(10))
    with pytest.raises(RecordError) as whole:
        _read_columns(path, KEEP, None)
    with pytest.raises(RecordError) as counted:
        _read_columns(path, KEEP, 0)
    assert str(counted.value) == str(whole.value)
    assert f"line {ROWS + 2} is longer" in str(whole.value)

"""Load a TOML file into a pydantic model, refusing bad files with the line, the key and what
was expected (contracts §4).

Both the service configuration (``plantcheck.toml``) and the simulator scenario use it.
TOML syntax errors carry their own line; validation errors are located by walking the file's
table headers and keys along the error's path (``loop[2].valve.S`` → the ``S =`` line inside
the third ``[[loop]]`` table, or its inline table).
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path
from typing import TypeVar

from pydantic import BaseModel, ValidationError

M = TypeVar("M", bound=BaseModel)

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")


class ConfigError(ValueError):
    """An unusable configuration file: ``str()`` is one line naming file, line, key and fix."""

    def __init__(self, path: str, line: int | None, key: str, expected: str) -> None:
        self.path, self.line, self.key, self.expected = path, line, key, expected
        where = f"{path}:{line}" if line else path
        super().__init__(f"{where}: {key}: {expected}")


def dotted(loc: tuple[int | str, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def locate(text: str, loc: tuple[int | str, ...]) -> int | None:
    """1-based line of the key at ``loc`` in the TOML ``text`` (best effort; None if unknown).

    Follows ``[table]`` / ``[[array]]`` headers for the leading path parts, then looks for the
    first remaining key inside that table's lines (``key =`` or ``key = {...}`` inline tables).
    """
    lines = text.splitlines()
    start, end = 0, len(lines)
    # descend through table headers: a header whose dotted name matches a prefix of loc
    i = 0
    header_path: list[str] = []
    while i < len(loc):
        part = loc[i]
        if not isinstance(part, str):
            i += 1
            continue
        name = ".".join([*header_path, part])
        nxt_part = loc[i + 1] if i + 1 < len(loc) else None
        index = nxt_part if isinstance(nxt_part, int) else None
        found = []
        prefix = ".".join(header_path)
        for n in range(start, len(lines)):
            m = _HEADER.match(lines[n])
            if not m:
                continue
            hname = m.group(2).replace(" ", "")
            if hname == name:
                found.append(n)
            elif prefix and not hname.startswith(prefix + "."):
                break  # left the enclosing table
        if not found:
            break
        pick = found[index] if index is not None and index < len(found) else found[0]
        start = pick + 1
        nxt = [n for n in range(start, len(lines)) if _HEADER.match(lines[n])]
        end = nxt[0] if nxt else len(lines)
        header_path.append(part)
        i += 2 if index is not None else 1
    remaining = [p for p in loc[i:] if isinstance(p, str)]
    if not remaining:
        return start if header_path else None
    for key in remaining:
        pat = re.compile(rf"(^|[{{,\s]){re.escape(key)}\s*=")
        for n in range(start, end):
            if pat.search(lines[n].split("#", 1)[0]):
                # a later key may be on the same line (inline table) or below it
                start = n
                break
        else:
            return start if header_path else None
    return start + 1


HINTS = {
    "int_type": "a whole number, written without quotes or decimal point",
    "float_type": "a number, written without quotes",
    "bool_type": "true or false, written without quotes",
    "string_type": "text in quotes",
}
"""What to write instead, by the error's kind: TOML values are taken as they are typed, never
converted (``port = "18520"`` is refused, not read as 18520)."""


def _expected(err: dict[str, object]) -> str:
    msg = str(err.get("msg", "invalid value"))
    kind = str(err.get("type", ""))
    if kind in HINTS:
        msg = f"{msg}: write {HINTS[kind]}"
    if kind == "extra_forbidden":
        return "unknown key (check its spelling against the documented keys)"
    if kind == "missing":
        return "required key is missing"
    got = err.get("input")
    if isinstance(got, (str, int, float, bool)) and kind != "missing":
        return f"{msg}; got {got!r}"
    return msg


def parse_toml(text: str, model: type[M], path: str = "<config>") -> M:
    """Validate TOML ``text`` as ``model``; raise ``ConfigError`` on the first problem.

    Strictly, as the JSON the file stands for: no value changes type on the way (a quoted
    number, a float where a whole number belongs, 1 for true are errors), while a whole
    number where any number belongs and an enum's text are what they say."""
    if text.startswith("\ufeff"):
        raise ConfigError(
            path, 1, "file", "starts with a UTF-8 byte-order mark (BOM): save it as UTF-8 "
            "without BOM (in Notepad: Save as, Encoding 'UTF-8')"
        )  # fmt: skip
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        raise ConfigError(
            path, int(m.group(1)) if m else None, "syntax", f"not valid TOML ({exc})"
        ) from None
    # TOML dates and times become text, which no numeric setting takes
    payload = json.dumps(data, default=str)
    try:
        return model.model_validate_json(payload, strict=True)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = tuple(err["loc"])
        raise ConfigError(
            path, locate(text, loc), dotted(loc) or "(file)", _expected(dict(err))
        ) from None


def load_toml(path: Path, model: type[M]) -> M:
    """Read and validate the TOML file at ``path`` (``ConfigError`` when unusable)."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(str(path), None, "file", "not found; give an existing path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(str(path), None, "file", f"cannot be read ({exc})") from None
    return parse_toml(text, model, str(path))

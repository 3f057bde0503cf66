"""Identifiers every layer agrees on: what a loop id or a source name may be.

One definition for the configuration, the API's path parameters, ``plantcheck import`` and the
simulator's scenarios, so an id accepted in one place is never refused (or stored unreachable)
in another: 1-64 characters of letters, digits, ``_``, ``.`` and ``-``, as DCS tag names are
(ISA-5.1 style ``FIC101``, ``10-PIC-301``), and safe in a URL path without escaping.
"""

from __future__ import annotations

import re

NAME_PATTERN = r"^[A-Za-z0-9_.\-]{1,64}$"
"""A loop id or source name."""
NAME_RULE = "1-64 letters, digits, '_', '.' or '-'"
"""The pattern in words, for error messages."""

_NAME = re.compile(NAME_PATTERN)


def check_loop_id(value: str) -> str:
    """``value`` when it is a valid loop id; ValueError naming the rule otherwise."""
    if not _NAME.match(value):
        raise ValueError(f"loop id {value!r} is not valid: use {NAME_RULE} (e.g. FIC101)")
    return value

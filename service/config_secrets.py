"""Secrets in the configuration: given inline, by an environment variable or by a file."""

from __future__ import annotations

import os
from pathlib import Path


def read_secret(what: str, inline: str, env: str, file: str) -> str | None:
    """A secret given at most one way: in the file (``inline``), by the name of an environment
    variable (``env``) or of a file whose first line holds it (``file``, e.g. a systemd
    credential); None when not given. ValueError naming ``what`` and the fix otherwise."""
    given = [k for k, v in (("inline", inline), ("_env", env), ("_file", file)) if v]
    name = what.rsplit(" ", 1)[-1]
    if len(given) > 1:
        keys = [name if k == "inline" else name + k for k in given]
        raise ValueError(f"{what}: give it one way, not {' and '.join(keys)}")
    if env:
        value = os.environ.get(env)
        if value is None:
            raise ValueError(
                f"{what}: {name}_env = {env!r} but that environment variable is not set (set "
                f"it, or use {name}_file)"
            )
        return value
    if file:
        try:
            lines = Path(file).read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise ValueError(
                f"{what}: {name}_file {file!r} cannot be read ({exc.strerror})"
            ) from None
        return lines[0] if lines else ""
    return inline or None

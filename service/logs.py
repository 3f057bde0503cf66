"""One logging configuration for every command (issue 27): a level, plain or JSON lines, and
the libraries kept at WARNING unless the level is ``debug``.

asyncua logs every publish response at INFO (0.7 GB a day for 8 loops, 61 MB in 5 minutes
during a fault); pymodbus, APScheduler and uvicorn's access log are as talkative. Our own
loggers (``plantcheck.*``) follow the chosen level.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import click

LEVELS = ("debug", "info", "warning", "error")
QUIET_LIBRARIES = (
    "asyncua",
    "pymodbus",
    "apscheduler",
    "uvicorn.access",
    "sqlalchemy",
    "alembic",
    "aiosqlite",
    "asyncpg",
    "httpx",
    "procrastinate",
)
"""Loggers held at WARNING unless the level is ``debug``."""

PLAIN = "%(asctime)s %(levelname)s %(name)s %(message)s"


@dataclass(frozen=True)
class LogOptions:
    """``--log-level`` and ``--log-format`` of the root command (None: the command's default)."""

    level: str | None = None
    fmt: Literal["plain", "json"] = "plain"


class JsonFormatter(logging.Formatter):
    """One JSON object per line: time (ISO 8601 UTC), level, logger, message, exception."""

    def format(self, record: logging.LogRecord) -> str:
        out = {
            "time": time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created))
            + f".{int(record.msecs):03d}Z",
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        if record.exc_info:
            out["exception"] = self.formatException(record.exc_info)
        return json.dumps(out, ensure_ascii=False)


class OneLineLibraryErrors(logging.Filter):
    """A library's error on one line, without its traceback (unless ``debug``).

    asyncua logs "Publish iteration crashed" with a full traceback at every lost connection;
    the connector already logs the failure once and its recovery once, so the library's
    traceback only fills the log. Our own loggers keep theirs: there it is a bug.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        if record.exc_info and not record.name.startswith("plantcheck"):
            exc = record.exc_info[1]
            record.msg = f"{record.getMessage()} ({type(exc).__name__}: {exc})"
            record.args = None
            record.exc_info = None
            record.exc_text = None
        return True


def configure_logging(
    level: str, fmt: Literal["plain", "json"] = "plain", libraries: str = "warning"
) -> None:
    """Configure the root logger once: ``level`` one of ``LEVELS``; libraries at
    ``libraries`` (WARNING) or above unless ``debug``."""
    handler = logging.StreamHandler()
    handler.setFormatter(JsonFormatter() if fmt == "json" else logging.Formatter(PLAIN))
    if level != "debug":
        handler.addFilter(OneLineLibraryErrors())
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level.upper())
    library_level = logging.DEBUG if level == "debug" else getattr(logging, libraries.upper())
    for name in QUIET_LIBRARIES:
        logging.getLogger(name).setLevel(max(library_level, root.level))


def _current_context() -> click.Context | None:
    """The running command's context: typer 0.2x runs its own copy of click, whose context
    stack ``click.get_current_context`` does not see (the root options were then ignored).
    The installed click is imported only when typer's copy finds no context (10 ms a start)."""
    try:
        from typer._click.globals import get_current_context
    except ImportError:  # a typer that runs the installed click
        pass
    else:
        ctx: click.Context | None = get_current_context(silent=True)  # type: ignore[assignment]
        if ctx is not None:
            return ctx
    import click

    return click.get_current_context(silent=True)


def configure_for_command(default_level: str, libraries: str = "warning") -> None:
    """Logging for the running command: the root command's options, else ``default_level``;
    the libraries at ``libraries`` or above (``configure_logging``)."""
    ctx = _current_context()
    opts = ctx.find_root().obj if ctx is not None else None
    if not isinstance(opts, LogOptions):
        opts = LogOptions()
    configure_logging(opts.level or default_level, opts.fmt, libraries)

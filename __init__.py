"""plantcheck: on-line monitoring and diagnosis of industrial control loops."""

from __future__ import annotations

from functools import cache

__all__ = ["__version__"]


@cache
def _installed_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("plantcheck")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
        return "0.0.0"


def __getattr__(name: str) -> str:
    """``plantcheck.__version__``, read from the installed metadata when first asked for
    (PEP 562): ``importlib.metadata`` costs 20-50 ms of every command's start, and ``diagnose``
    of one record (issue 46's 0.7 s budget) never shows the version."""
    if name == "__version__":
        return _installed_version()
    raise AttributeError(f"module 'plantcheck' has no attribute {name!r}")

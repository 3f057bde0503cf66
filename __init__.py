"""plantcheck: on-line monitoring and diagnosis of industrial control loops."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("plantcheck")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0"

__all__ = ["__version__"]

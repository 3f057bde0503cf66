"""The store's one error type, importable without the database libraries."""

from __future__ import annotations


class StorageError(RuntimeError):
    """The store cannot be used; the message names the problem and the fix."""

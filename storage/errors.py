"""The store's one error type, importable without the database libraries."""

from __future__ import annotations


class StorageError(RuntimeError):
    """The store cannot be used; the message names the problem and the fix."""


def store_outage_errors() -> tuple[type[Exception], ...]:
    """Exceptions that mean the database cannot be reached right now (not a bug): the API
    answers them with 503 and Retry-After. SQLAlchemy wraps the drivers' errors in
    ``DBAPIError``; a refused or reset connection can also surface as ``OSError``."""
    from sqlalchemy.exc import DBAPIError

    return (StorageError, DBAPIError, OSError, TimeoutError)

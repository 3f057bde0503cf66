"""storage (built by a later issue)."""

"""connectors (built by a later issue)."""

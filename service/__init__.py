"""Service layer: record files, command-line interface (and later the scheduler)."""

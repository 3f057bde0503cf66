"""Storage: samples, gap markers, diagnoses and stiction estimates in SQLite (default) or
PostgreSQL (SQLAlchemy), the durable write buffer and the schema migrations."""

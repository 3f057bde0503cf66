"""The store's tables (SQLAlchemy Core), one definition for SQLite and PostgreSQL.

Times are integers: microseconds since 1970-01-01 UTC (``*_us``), exact, compact and cheap to
index and to bulk-copy on both databases. Quality is the 32-bit OPC UA status code for every
sample whatever its protocol (0 = Good; a value is NULL whenever the status is Bad).
"""

from __future__ import annotations

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    Column,
    Float,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    UniqueConstraint,
    true,
)

metadata = MetaData()

sources = Table(
    "sources",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("name", String(64), nullable=False, unique=True),
    Column("protocol", String(16), nullable=False),
    Column("endpoint", String(256), nullable=False, default=""),
)

source_health = Table(
    "source_health",
    metadata,
    # the last health report of each source from the process that reads it (a collector at the
    # plant, or the service): the central API shows sources it does not read itself (issue 28)
    Column("name", String(64), primary_key=True),
    Column("collector", String(64), nullable=False, default=""),
    Column("protocol", String(16), nullable=False),
    Column("state", String(16), nullable=False),
    Column("since_us", BigInteger, nullable=True),
    Column("last_good_sample_us", BigInteger, nullable=True),
    Column("failures", Integer, nullable=False, default=0),
    Column("last_error", Text, nullable=False, default=""),
    Column("reported_us", BigInteger, nullable=False),
)

loops = Table(
    "loops",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("name", String(64), nullable=False, unique=True),
    Column("type", String(16), nullable=False, default="other"),
    Column("source", String(64), nullable=False, default=""),
    Column("description", Text, nullable=False, default=""),
    Column("state", String(16), nullable=False, default="unknown"),
    Column("cause", String(32), nullable=True),
    Column("since_us", BigInteger, nullable=True),
    Column("last_diagnosis_us", BigInteger, nullable=True),
    # where the loop sits and how much it matters (configuration), and the indices of its
    # latest diagnosis: what the table sorts and filters by (issue 49)
    Column("area", String(64), nullable=False, default="", server_default=""),
    Column("unit", String(64), nullable=False, default="", server_default=""),
    Column("criticality", Integer, nullable=True),
    Column("kpis", JSON, nullable=True),
)

tags = Table(
    "tags",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("loop_id", Integer, ForeignKey("loops.id", ondelete="CASCADE"), nullable=False),
    Column("signal", String(8), nullable=False),
    Column("address", String(256), nullable=False),
    UniqueConstraint("loop_id", "signal", name="uq_tags_loop_signal"),
)

samples = Table(
    "samples",
    metadata,
    Column("tag_id", Integer, primary_key=True),
    Column("ts_us", BigInteger, primary_key=True),
    Column("recv_us", BigInteger, nullable=False),
    Column("value", Float, nullable=True),
    Column("status", BigInteger, nullable=False, default=0),
    # SQLite: rows clustered on (tag_id, ts_us), so a window of one tag is one sequential range
    # scan instead of a table lookup per row (rows of all tags arrive interleaved in time)
    sqlite_with_rowid=False,
)

sample_hours = Table(
    "sample_hours",
    metadata,
    # one row per tag and hour of Good samples: the long trends outlive the samples' retention
    Column("tag_id", Integer, primary_key=True),
    Column("hour_us", BigInteger, primary_key=True),
    Column("n", Integer, nullable=False),
    Column("mean", Float, nullable=False),
    Column("low", Float, nullable=False),
    Column("high", Float, nullable=False),
    sqlite_with_rowid=False,
)

diagnoses = Table(
    "diagnoses",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("loop_id", Integer, ForeignKey("loops.id", ondelete="CASCADE"), nullable=False),
    Column("created_us", BigInteger, nullable=False),
    Column("window_start_us", BigInteger, nullable=False),
    Column("window_end_us", BigInteger, nullable=False),
    Column("cause", String(32), nullable=False),
    Column("state", String(16), nullable=False),
    Column("payload", JSON, nullable=False),
    Index("ix_diagnoses_loop_time", "loop_id", "window_end_us"),
)

stiction_estimates = Table(
    "stiction_estimates",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("loop_id", Integer, ForeignKey("loops.id", ondelete="CASCADE"), nullable=False),
    Column("at_us", BigInteger, nullable=False),
    Column("S", Float, nullable=False),
    Column("J", Float, nullable=True),
    Column("source", String(16), nullable=False, default="op_pv"),
    # how S was estimated (contracts §2 stiction.estimate.method, or "measured" from MV) and
    # whether the estimate passed its rules: the trend report never mixes methods silently
    Column("method", String(16), nullable=False, server_default="hammerstein"),
    Column("reliable", Boolean, nullable=False, server_default=true()),
    Index("ix_stiction_loop_time", "loop_id", "at_us"),
)

stiction_trends = Table(
    "stiction_trends",
    metadata,
    # each valve's trend as of its latest estimate (``storage/trends.py``): computed when an
    # estimate is stored, so the report only reads it
    Column("loop_id", Integer, ForeignKey("loops.id", ondelete="CASCADE"), primary_key=True),
    Column("computed_us", BigInteger, nullable=False),
    Column("method", String(16), nullable=True),
    Column("limit_s", Float, nullable=False),
    Column("current_s", Float, nullable=True),
    Column("current_j", Float, nullable=True),
    Column("slope_per_week", Float, nullable=True),
    Column("above_limit", Boolean, nullable=False),
    Column("projected_crossing_us", BigInteger, nullable=True),
    Column("used", Integer, nullable=False),
    Column("note", Text, nullable=False),
)

actions = Table(
    "actions",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("loop_id", Integer, ForeignKey("loops.id", ondelete="CASCADE"), nullable=False),
    Column("cause", String(32), nullable=False),
    Column("code", String(48), nullable=False),
    Column("text", Text, nullable=False),
    Column("priority", Integer, nullable=False, default=3),
    Column("since_us", BigInteger, nullable=False),
    Column("active", Boolean, nullable=False, default=True),
    Column("closed_us", BigInteger, nullable=True),
    Index("ix_actions_active", "active", "loop_id"),
)

plant_oscillations = Table(
    "plant_oscillations",
    metadata,
    # each plant-wide pass (``service/plant_oscillations.py``): the groups of loops oscillating
    # together and their sources, as the API serves them; the latest few are kept
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("at_us", BigInteger, nullable=False),
    Column("groups", JSON, nullable=False),
)

alerts = Table(
    "alerts",
    metadata,
    # the alert outbox (``service/alerts.py``): one row per message to one target, written in
    # the transaction of the verdict change it reports, delivered (and retried) from here
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("loop_id", Integer, ForeignKey("loops.id", ondelete="CASCADE"), nullable=False),
    Column("key", String(200), nullable=False, unique=True),
    Column("rule", String(64), nullable=False),
    Column("target", String(64), nullable=False),
    Column("state", String(16), nullable=False),
    Column("cause", String(32), nullable=False),
    Column("payload", JSON, nullable=False),
    Column("status", String(16), nullable=False, default="pending"),
    Column("attempts", Integer, nullable=False, default=0),
    Column("created_us", BigInteger, nullable=False),
    Column("next_try_us", BigInteger, nullable=False),
    Column("delivered_us", BigInteger, nullable=True),
    Column("last_error", Text, nullable=False, default=""),
    Index("ix_alerts_due", "status", "next_try_us"),
    Index("ix_alerts_quiet", "loop_id", "rule", "created_us"),
)

"""Rolling-window diagnosis of every loop (APScheduler 3.11 ``AsyncIOScheduler``).

Each loop gets an interval job (its ``period_s``, default 10 min) that reads the loop's last
``window_s`` seconds (default 2 h) from the store, runs the diagnosis chain in a worker process
(``ProcessPoolExecutor``: the event loop that ingests and serves never blocks on numpy) and
stores the diagnosis, its suggested action and any stiction estimate. The Hammerstein S/J
estimate (methods §6.1, the costly step: about 0.5-1 s a window) is made at most every
``quantify_every_s`` (default 1 h) per loop once it was reliable: enough for a trend over
weeks, and only when the previous diagnosis found the valve sticky too (one odd window costs no
estimate). An estimate that fails the reliability rules is tried again after one period, then
after twice as long each time, up to ``quantify_every_s``: a valve whose estimate stays
unreliable costs one attempt an hour, not one every run. While the window is still filling
(less stored than ``window_s``) it is tried at every run, as each holds more periods. A loop's
verdict (state, cause, ``since``) changes only when ``confirm`` consecutive diagnoses (default
2) find the same new cause, so one odd window does not flip the health table; every diagnosis
is kept in the history whatever its cause. Verdicts are committed in batches
(``storage.verdict_writer``: the verdicts of a quarter second in one transaction).

Windows are kept in memory between runs (``storage.window_cache``): a run reads only the
samples stored since the last one. The window ends at the loop's newest stored sample (source
time), so a plant whose clock runs ahead of or behind this server, or an accelerated simulator,
is judged on its own time base; when the newest sample is older than a whole window, the window
ends now and the chain reports the missing data. One scheduler per deployment: two
``plantcheck run`` processes on one database would diagnose every loop twice.
"""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
import os
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np
from apscheduler.schedulers.asyncio import AsyncIOScheduler

from plantcheck.api.deps import iso_required
from plantcheck.diagnosis.result import action_for, priority_of, state_of
from plantcheck.diagnosis.tuning_proposal import TUNING_CAUSES
from plantcheck.service.alert_rules import LoopAlertRule, drafts_for
from plantcheck.service.blas_threads import one_blas_thread
from plantcheck.service.metrics import ServiceMetrics
from plantcheck.service.window_diagnosis import diagnose_window, warm_worker
from plantcheck.service.worker_lifetime import die_with_parent
from plantcheck.storage.results import (
    QUANTIFIED_CAUSES,
    PendingVerdict,
    Verdict,
    healthy_error_sd,
    loop_states,
    recent_history,
)
from plantcheck.storage.store import LoopRow, Store
from plantcheck.storage.verdict_writer import VerdictWriter
from plantcheck.storage.window import HELD
from plantcheck.storage.window_cache import WindowCache

log = logging.getLogger("plantcheck.scheduler")


def stored_estimate(payload: dict[str, Any]) -> tuple[float, float | None, str, bool] | None:
    """The stiction size a diagnosis leaves for the trend report: (S, J, method, reliable).

    ``stiction.S``/``J`` (the reliable Hammerstein estimate, or the stem position's measure in
    the advanced chain: method ``measured``) first; else the chain's best other size,
    ``stiction.estimate`` (stick-slip events or the PV(OP) ellipse), with its method and
    reliability, so that maintenance planners get a size for every sticky valve and the report
    can keep the methods apart.
    """
    stiction = payload.get("stiction") or {}
    J = stiction.get("J")
    if stiction.get("S") is not None:
        measured = (payload.get("valve") or {}).get("state") in QUANTIFIED_CAUSES
        return float(stiction["S"]), J, "measured" if measured else "hammerstein", True
    est = stiction.get("estimate") or {}
    if est.get("S") is None:
        return None
    return float(est["S"]), est.get("J"), str(est.get("method")), bool(est.get("reliable"))


@dataclass(frozen=True)
class LoopSchedule:
    """When and over what window one loop is diagnosed (seconds)."""

    name: str
    loop_type: str
    window_s: float
    period_s: float
    hold: tuple[str, ...] = HELD
    """Signals that keep their value between samples (all of them for OPC UA sources, which
    report changes only; SP and mode otherwise)."""
    stiction_limit: float = 2.0
    """The valve's S limit, % of travel (its trend's projection)."""
    dead_time_s: float | None = None
    """The configured process dead time (s), for the Harris index."""
    controller: tuple[tuple[str, object], ...] = ()
    """The controller's form (``ControllerConfig`` items): the retuning's output form."""
    description: str = ""
    area: str = ""
    criticality: int | None = None
    alert_rules: tuple[LoopAlertRule, ...] = ()
    """The alert rules that apply to this loop (``alert_rules.rules_for_loop``)."""


@dataclass
class LoopJobState:
    """Last outcome of a loop's job (for logging failures once and ``/readyz``)."""

    failing: bool = False
    last_cause: str | None = None
    streak: int = 0
    """Consecutive diagnoses that found ``last_cause``."""
    streak_since_us: int = 0
    quantify_due: float = -float("inf")
    """When (monotonic s) S and J may next be estimated for this loop."""
    quantify_backoff_s: float = 0.0
    """Wait after the last unreliable estimate (0 after a reliable one)."""
    confirmed: str | None = None
    """The cause this process last adopted for the loop (None: not known here)."""
    baseline: tuple[float, str] | None = None
    """The loop's healthy error σ and where it came from (``BASELINE_REFRESH_S``)."""
    baseline_due: float = -float("inf")
    """When (monotonic s) the baseline is next read from the store."""


def judges_tuning(payload: dict[str, Any]) -> bool:
    """Whether a diagnosis read the loop's tuning from something: a set-point step response,
    a load recovery, Hägglund's idle index, or an oscillation."""
    ind = payload.get("indices") or {}
    keys = ("sp_step_slowness", "load_recovery_slowness", "idle_index")
    return bool(payload.get("oscillating")) or any(ind.get(k) is not None for k in keys)


BASELINE_REFRESH_S = 6 * 3600.0
"""How often a loop's baseline is read again from its stored diagnoses (s)."""


def _now_us() -> int:
    return time.time_ns() // 1000


class DiagnosisScheduler:
    """Owns the APScheduler instance and the worker pool of one service."""

    def __init__(
        self,
        store: Store,
        schedules: list[LoopSchedule],
        workers: int = 2,
        metrics: ServiceMetrics | None = None,
        first_run_within_s: float = 30.0,
        confirm: int = 2,
        quantify_every_s: float = 3600.0,
        window_cache_mb: float = 256.0,
        baseline_days: float = 28.0,
        baseline_min: int = 6,
    ) -> None:
        self.store = store
        self.baseline_days = baseline_days
        self.baseline_min = baseline_min
        self.schedules = {s.name: s for s in schedules}
        self.workers = workers
        self.metrics = metrics or ServiceMetrics()
        self.first_run_within_s = first_run_within_s
        self.confirm = confirm
        self.quantify_every_s = quantify_every_s
        self.state = {s.name: LoopJobState() for s in schedules}
        self._scheduler: Any = None
        self._pool: ProcessPoolExecutor | None = None
        self._slots = asyncio.Semaphore(workers)
        self._reads = asyncio.Semaphore(workers + 1)
        self._loops: dict[str, LoopRow] = {}
        longest = max((s.window_s for s in schedules), default=3600.0)
        self.windows = WindowCache(store, int(window_cache_mb * 2**20), refresh_s=longest)
        self.verdicts = VerdictWriter(store)
        self._states_stale = False
        self._states_task: asyncio.Task[None] | None = None
        self._in_flight: set[asyncio.Task[Any]] = set()
        """The scheduled runs under way (drained by :meth:`stop`)."""

    @property
    def running(self) -> bool:
        return self._scheduler is not None and bool(self._scheduler.running)

    async def start(self) -> None:
        """Start the worker pool and one interval job per loop, first runs spread over
        ``first_run_within_s`` (or the period, when shorter)."""
        await self.open_pool()
        self._scheduler = AsyncIOScheduler(timezone="UTC")
        n = max(1, len(self.schedules))
        now = time.time()
        for i, s in enumerate(self.schedules.values()):
            first = now + 1.0 + min(self.first_run_within_s, s.period_s) * i / n
            self._scheduler.add_job(
                self.run_loop,
                "interval",
                seconds=s.period_s,
                args=[s.name],
                id=s.name,
                next_run_time=datetime.fromtimestamp(first, UTC),
                max_instances=1,
                coalesce=True,
                misfire_grace_time=max(1, int(s.period_s)),
            )
        self._scheduler.start()
        log.info("diagnosis scheduled for %d loops on %d workers", n, self.workers)

    async def open_pool(self) -> None:
        """Start the worker processes (spawned: no inherited event loop or database handles)
        and read the loops' tag mapping."""
        self._loops = await self.store.loops()
        # a spawned worker loads numpy before any initializer runs: the setting goes into the
        # environment it inherits (the command line has set it already; a host program may not)
        one_blas_thread()
        ctx = multiprocessing.get_context("spawn")
        self._pool = ProcessPoolExecutor(
            max_workers=self.workers,
            mp_context=ctx,
            initializer=die_with_parent,
            initargs=(os.getpid(),),
        )
        loop = asyncio.get_running_loop()
        await asyncio.gather(
            *(loop.run_in_executor(self._pool, warm_worker) for _ in range(self.workers))
        )

    async def stop(self, drain_s: float = 10.0) -> None:
        """Stop scheduling, let the diagnoses under way finish (at most ``drain_s`` seconds;
        the scheduler cancels the rest) and write their verdicts, then close the pool."""
        if self._scheduler is not None and self._scheduler.running:
            self._scheduler.pause()
            if self._in_flight:
                _, late = await asyncio.wait(set(self._in_flight), timeout=drain_s)
                if late:
                    log.warning(
                        "%d diagnoses still running after %g s at shutdown: cancelled, "
                        "they run again at the next start",
                        len(late),
                        drain_s,
                    )
            self._scheduler.shutdown(wait=False)
        await self.verdicts.close()
        if self._states_task is not None:
            await self._states_task
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    async def adopt_shared_history(self, names: Sequence[str]) -> None:
        """Take each loop's last causes and identification time from the store.

        Diagnosis workers on the job queue (issue 28) get a batch of loops wherever it lands, so
        the confirmation streak (``confirm``), the cause that decides whether S is estimated and
        the time of the last identified S come from the stored history, read before each batch
        (two queries), not from this process's memory. An unreliable estimate's back-off stays
        per process: a valve whose estimate keeps failing costs at most one attempt per worker
        per ``quantify_every_s``.
        """
        if any(n not in self._loops for n in names):
            self._loops = await self.store.loops()
        rows = [self._loops[n] for n in names if n in self._loops and n in self.state]
        history = await recent_history(self.store, [r.id for r in rows], max(1, self.confirm))
        now = time.monotonic()
        for row in rows:
            h, st = history[row.id], self.state[row.name]
            st.last_cause, st.streak = None, 0
            for cause, created_us in h.causes:
                if st.last_cause not in (None, cause):
                    break
                st.last_cause, st.streak, st.streak_since_us = cause, st.streak + 1, created_us
            if h.last_identified_us is not None and h.last_window_end_us is not None:
                age_s = (h.last_window_end_us - h.last_identified_us) / 1e6
                st.quantify_due = max(st.quantify_due, now + self.quantify_every_s - age_s)

    async def run_loop(self, name: str) -> str | None:
        """Diagnose loop ``name`` now; returns its cause (None when the job failed)."""
        task = asyncio.current_task()
        if task is None:  # not run as a task (never by the scheduler): nothing to drain
            return await self._run_loop(name)
        self._in_flight.add(task)
        try:
            return await self._run_loop(name)
        finally:
            self._in_flight.discard(task)

    async def _run_loop(self, name: str) -> str | None:
        sched = self.schedules[name]
        st = self.state[name]
        t0 = time.perf_counter()
        try:
            cause = await self._diagnose(sched)
        except Exception as exc:
            self.metrics.diagnoses.labels("failed").inc()
            if not st.failing:
                log.warning("diagnosis of %s failed: %s (logged once until it recovers)", name, exc)
            st.failing = True
            return None
        if st.failing:
            log.info("diagnosis of %s recovered", name)
        st.failing = False
        self.metrics.diagnoses.labels("done").inc()
        self.metrics.diagnosis_duration.observe(time.perf_counter() - t0)
        return cause

    async def _diagnose(self, sched: LoopSchedule) -> str:
        row = self._loops.get(sched.name)
        if row is None:  # configured after the pool started: map it now
            self._loops = await self.store.loops()
            row = self._loops[sched.name]
        now_us = _now_us()
        async with self._reads:  # windows read ahead while the workers diagnose
            latest = await self.windows.read_latest(
                row, int(sched.window_s * 1e6), sched.hold, now_us
            )
        self.metrics.window_cache_bytes.set(self.windows.nbytes)
        win, start_us, end_us, notes = latest.window, latest.start_us, latest.end_us, latest.notes
        values = {k: v for k, v in win.values.items() if k in win.signals or k in ("pv", "op")}
        st = self.state[sched.name]
        # due half a period early at most: runs come a period apart, never exactly
        due = time.monotonic() >= st.quantify_due - sched.period_s / 2
        # only once a second window finds the valve sticky: one odd window costs no estimate
        quantify = due and st.last_cause in QUANTIFIED_CAUSES
        assert self._pool is not None, "scheduler not started"
        baseline = await self._baseline(row, st)
        async with self._slots:
            payload = await asyncio.get_running_loop().run_in_executor(
                self._pool,
                diagnose_window,
                values,
                win.sample_time_s,
                sched.loop_type,
                notes,
                quantify,
                baseline,
                dict(sched.controller),
                sched.dead_time_s,
            )
        if quantify:
            # a window still filling holds more periods at the next run
            self._schedule_quantification(st, payload, sched.period_s, latest.filling)
        elif payload["cause"] in QUANTIFIED_CAUSES and payload.get("chain") != "advanced":
            payload["notes"].append(
                "S and J not estimated in this window: "
                + (
                    "first window with this cause, estimated when the next one confirms it"
                    if due
                    else f"estimated at most every {self.quantify_every_s:g} s (the latest "
                    "estimate stays in the loop table)"
                )
            )
        await self._store(row, payload, start_us, end_us, now_us)
        return str(payload["cause"])

    async def _baseline(self, row: LoopRow, st: LoopJobState) -> tuple[float, str] | None:
        """The loop's own normal (issue 46 item 5): the median error σ of its ``ok``
        diagnoses over ``baseline_days``, once ``baseline_min`` of them exist; read from the
        store at most every ``BASELINE_REFRESH_S``."""
        if self.baseline_days <= 0 or time.monotonic() < st.baseline_due:
            return st.baseline
        st.baseline_due = time.monotonic() + BASELINE_REFRESH_S
        since = _now_us() - int(self.baseline_days * 86_400e6)
        sds = await healthy_error_sd(self.store, row, since)
        if len(sds) >= self.baseline_min:
            st.baseline = (
                float(np.median(sds)),
                f"median of {len(sds)} healthy diagnoses over {self.baseline_days:g} days",
            )
        return st.baseline

    def _schedule_quantification(
        self, st: LoopJobState, payload: dict[str, Any], period_s: float, filling: bool
    ) -> None:
        """Set when the loop's next S/J estimate is due after a diagnosis that could make one.

        An unreliable estimate from a window still filling (a service just started, a loop just
        added) is tried again at the next run without backing off: that window is one period
        longer, and the commonest failure there is too few oscillation periods (at least 10,
        methods §6.1). Backing off then put the first S long after the data allowed it: the
        bundled plant over Modbus at 20x showed FIC801's S 80 s after its cause, at 114 s,
        where 10 of its 153-s periods take 77 s. With 2-h windows every 10 min, a valve
        cycling every 5.5 min (10 periods in 55 min), sticky from the second run on, was tried
        at 20, 30, 50 and 90 min; now at every run from 20 min, so S comes at 60."""
        stiction = payload.get("stiction") or {}
        attempted = "quantification" in stiction or "op_pv_estimate" in stiction
        if stiction.get("S") is not None:  # reliable (or measured from MV)
            st.quantify_backoff_s = 0.0
            st.quantify_due = time.monotonic() + self.quantify_every_s
        elif attempted and filling:
            st.quantify_due = time.monotonic() + period_s
        elif attempted:
            st.quantify_backoff_s = min(
                self.quantify_every_s, max(period_s, 2 * st.quantify_backoff_s)
            )
            st.quantify_due = time.monotonic() + st.quantify_backoff_s

    async def _store(
        self, row: LoopRow, payload: dict[str, Any], start_us: int, end_us: int, now_us: int
    ) -> None:
        cause = str(payload["cause"])
        estimate = stored_estimate(payload) if cause in QUANTIFIED_CAUSES else None
        S, J, method, reliable = estimate or (None, None, "hammerstein", True)
        action = (payload.get("actions") or [action_for(cause, S, J, method)])[0]
        verdict = Verdict(
            loop=row,
            created_us=now_us,
            window_start_us=start_us,
            window_end_us=end_us,
            cause=cause,
            state=state_of(cause),
            payload=payload,
            action_code=action["code"],
            action_text=action["text"],
            priority=priority_of(cause),
            S=None if S is None else float(S),
            J=None if J is None else float(J),
            stiction_source="mv" if method == "measured" else "op_pv",
            stiction_method=method,
            stiction_reliable=reliable,
            stiction_limit=self.schedules[row.name].stiction_limit,
        )
        st = self.state[row.name]
        if cause == "ok" and st.confirmed in TUNING_CAUSES and not judges_tuning(payload):
            # a window with no set-point move, no load recovery and no idle index cannot show
            # that a badly tuned loop got better: it confirms nothing (issue 46: the demo's
            # sluggish loop read ok in two quiet windows and lost its action for a while)
            st.last_cause, st.streak, st.streak_since_us = cause, 0, now_us
        elif cause == st.last_cause:
            st.streak += 1
        else:
            st.last_cause, st.streak, st.streak_since_us = cause, 1, now_us
        adopt = st.streak >= self.confirm
        if adopt:
            st.confirmed = cause
        sched = self.schedules[row.name]
        drafts = drafts_for(
            sched.alert_rules,
            {
                "loop": row.name, "type": sched.loop_type, "description": sched.description,
                "state": verdict.state, "cause": cause, "action": verdict.action_text,
                "since": iso_required(st.streak_since_us), "area": sched.area,
                "criticality": sched.criticality,
            },
        ) if adopt else ()  # fmt: skip
        pending = PendingVerdict(verdict, adopt, st.streak_since_us, drafts)
        if await self.verdicts.write(pending):
            log.info("%s: %s (%s)", row.name, cause, verdict.state)
            self._count_states_soon()

    def _count_states_soon(self) -> None:
        """Recount the loops per state (``plantcheck_loops``) once for all the verdicts that
        changed together (a batch commits many; one count each cost ~1 ms of event loop)."""
        self._states_stale = True
        if self._states_task is None or self._states_task.done():
            self._states_task = asyncio.create_task(self._count_states(), name="count-states")

    async def _count_states(self) -> None:
        while self._states_stale:
            self._states_stale = False
            try:
                self.metrics.set_loop_states(await loop_states(self.store))
            except Exception as exc:  # the gauge keeps its last counts; the next change retries
                log.warning("counting loops per state failed: %s", exc)
                return

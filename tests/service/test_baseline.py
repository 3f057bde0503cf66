"""A loop's own normal in the service (issue 46 item 5): the median error σ of its healthy
diagnoses in the store, used by the next diagnosis of a window far from it."""

from __future__ import annotations

import asyncio
import dataclasses
import time

import numpy as np
from helpers import verdict_of

from plantcheck.service.config import Config
from plantcheck.service.runtime import schedules_of
from plantcheck.service.scheduler import DiagnosisScheduler, LoopJobState
from plantcheck.service.window_diagnosis import diagnose_window
from plantcheck.simulator.cases import simc_pi
from plantcheck.simulator.loop import Disturbance, LoopConfig, Process, simulate_loop
from plantcheck.storage.results import PendingVerdict, record_verdicts
from plantcheck.storage.store import Store

CONFIG = Config.model_validate(
    {
        "source": [{"name": "s", "protocol": "opcua", "url": "opc.tcp://127.0.0.1:1/"}],
        "loop": [{"id": "TIC1", "source": "s", "pv": "ns=2;s=T.PV", "op": "ns=2;s=T.OP"}],
    }
)


def test_the_baseline_is_the_median_of_recent_healthy_diagnoses(db_url: str) -> None:
    async def body() -> None:
        store = await Store.open(db_url)
        try:
            row = (await store.sync_config(CONFIG))["TIC1"]
            now = time.time_ns() // 1000
            hour = 3_600_000_000
            batch = []
            for k, (cause, sd) in enumerate(
                [("ok", 0.10), ("ok", 0.12), ("stiction", 5.0), ("ok", 0.14), ("ok", 0.11)]
            ):
                v = verdict_of(row, now - (k + 1) * hour, cause)
                payload = {"cause": cause, "indices": {"error_std": sd}}
                batch.append(PendingVerdict(dataclasses.replace(v, payload=payload)))
            # a healthy diagnosis from before the baseline's days does not count
            old = verdict_of(row, now - 40 * 24 * hour, "ok")
            batch.append(PendingVerdict(dataclasses.replace(
                old, payload={"cause": "ok", "indices": {"error_std": 9.0}})))  # fmt: skip
            for item in sorted(batch, key=lambda b: b.verdict.window_end_us):
                await record_verdicts(store, [item])
            sched = DiagnosisScheduler(store, schedules_of(CONFIG), 1, baseline_min=4)
            st = LoopJobState()
            base = await sched._baseline(row, st)
            assert base is not None and abs(base[0] - 0.115) < 1e-9
            assert base[1] == "median of 4 healthy diagnoses over 28 days"
            # read again only after BASELINE_REFRESH_S; fewer than baseline_min: none
            assert await sched._baseline(row, st) == base
            strict = DiagnosisScheduler(store, schedules_of(CONFIG), 1, baseline_min=5)
            assert await strict._baseline(row, LoopJobState()) is None
            off = DiagnosisScheduler(store, schedules_of(CONFIG), 1, baseline_days=0)
            assert await off._baseline(row, LoopJobState()) is None
        finally:
            await store.close()

    asyncio.run(body())


def test_a_window_far_from_its_baseline_is_not_ok() -> None:
    proc = Process("fopdt", K=1.0, tau_s=20.0, theta_s=5.0)
    cfg = LoopConfig(process=proc, controller=simc_pi(proc), noise_std=0.8, n_samples=3000,
                     disturbances=(Disturbance(filtered_noise_std=0.3),), seed=3)  # fmt: skip
    r = simulate_loop(cfg)
    values = {"pv": r.pv, "op": r.op, "sp": r.sp}
    plain = diagnose_window(values, 1.0, "temperature", quantify=False)
    assert plain["cause"] == "ok" and plain["indices"]["error_std"] > 0.5
    out = diagnose_window(values, 1.0, "temperature", quantify=False,
                          baseline=(0.14, "median of 9 healthy diagnoses"))  # fmt: skip
    assert out["cause"] == "performance_degraded", out["notes"]
    assert out["indices"]["variability_ratio"] > 3 and out["actions"][0]["code"] == (
        "investigate_degradation"
    )
    assert np.isfinite(out["indices"]["op_std"])


def test_a_quiet_window_does_not_clear_a_tuning_verdict(db_url: str) -> None:
    """Issue 46: the demo's sluggish loop read ok in windows with no load, no set-point move
    and no idle index, and lost its verdict and action for a while. Such a window confirms
    nothing; windows that did judge the tuning still clear it."""
    from plantcheck.storage.results import loop_statuses

    def payload(cause: str, **indices: float) -> dict[str, object]:
        return {"cause": cause, "oscillating": False, "indices": indices, "notes": [],
                "actions": [], "stiction": {}}  # fmt: skip

    async def body() -> None:
        store = await Store.open(db_url)
        sched = DiagnosisScheduler(store, schedules_of(CONFIG), 1, confirm=2)
        try:
            row = (await store.sync_config(CONFIG))["TIC1"]
            t = time.time_ns() // 1000

            async def feed(*payloads: dict[str, object]) -> str:
                nonlocal t
                for p in payloads:
                    t += 1_000_000
                    await sched._store(row, p, t - 3_600_000_000, t, t)
                return {s.id: s.cause for s in await loop_statuses(store)}["TIC1"]

            slow = payload("sluggish_tuning", load_recovery_slowness=6.0)
            quiet = payload("ok")
            judged = payload("ok", idle_index=-0.3)
            assert await feed(slow, slow) == "sluggish_tuning"
            assert await feed(judged, quiet, quiet, judged, slow) == "sluggish_tuning"
            assert await feed(judged, judged) == "ok"
            # a loop never found badly tuned becomes ok on quiet windows as before
            assert await feed(payload("stiction"), payload("stiction"), quiet, quiet) == "ok"
        finally:
            await sched.verdicts.close()
            await store.close()

    asyncio.run(body())

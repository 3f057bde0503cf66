"""Issues 48 and 49 end to end: a sluggish loop's record imported into the store, the service's
diagnosis carries the identified process and a setting in the loop's configured controller
form, and the loop page shows it with the predicted responses (Chromium)."""

from __future__ import annotations

import json
import re
import subprocess
from datetime import timedelta
from pathlib import Path

import httpx
import numpy as np
import pytest
from helpers import free_port
from servicehelpers import CLI, dump_dom, record_start, start_service, wait_diagnosed

from plantcheck.simulator.tuning_cases import tuning_case


@pytest.mark.slow(minutes=0.5)  # 20-30 s: started early, not last
def test_a_sluggish_loop_gets_its_setting_on_the_page(tmp_path: Path) -> None:
    case = tuning_case(11001, "sluggish", loads=0.3)
    r = case.record
    duration = r.pv.size * case.ts
    start = record_start(duration)
    rows = ["timestamp,sp,pv,op"]
    for k in range(r.pv.size):
        t = (start + timedelta(seconds=k * case.ts)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3]
        rows.append(f"{t}Z,{r.sp[k]:.4f},{r.pv[k]:.4f},{r.op[k]:.4f}")
    record = tmp_path / "TIC9.csv"
    record.write_text("\n".join(rows) + "\n", encoding="utf-8")
    port = free_port()
    config = tmp_path / "plantcheck.toml"
    config.write_text(
        f'[storage]\nurl = "sqlite+aiosqlite:///{tmp_path / "plant.db"}"\n'
        f'buffer_path = "{tmp_path / "buffer.db"}"\n'
        f"[api]\nport = {port}\n"
        f"[scheduler]\nwindow_s = {int(np.ceil(duration)) + 60}\nperiod_s = 3\nconfirm = 1\n"
        '[[source]]\nname = "dcs"\nprotocol = "opcua"\n'
        f'url = "opc.tcp://127.0.0.1:{free_port()}/none/"\ndown_grace_s = 86400\n'
        '[[loop]]\nid = "TIC9"\ntype = "flow"\nsource = "dcs"\n'
        'sp = "ns=2;s=TIC9.SP"\npv = "ns=2;s=TIC9.PV"\nop = "ns=2;s=TIC9.OP"\n'
        'controller = { gain = "proportional_band", integral = "minutes", pv_span = 100.0 }\n',
        encoding="utf-8",
    )
    for args in (
        ["db", "upgrade", "--config", str(config)],
        ["import", str(record), "--loop", "TIC9", "--loop-type", "flow", "--config", str(config)],
    ):
        subprocess.run([*CLI, *args], check=True, capture_output=True)
    svc = start_service(config, port, {}, start)
    try:
        wait_diagnosed(svc.url, 1)
        d = httpx.get(f"{svc.url}/api/v1/loops/TIC9", timeout=10).json()["diagnosis"]
        assert d["cause"] == "sluggish_tuning", d["notes"]
        t = d["tuning"]
        assert t["proposed"] is not None and t["model"]["type"] == "fopdt", t["note"]
        assert t["dcs"]["gain_unit"] == "% (proportional band)"
        action = httpx.get(f"{svc.url}/api/v1/actions", timeout=10).json()[0]["action"]
        assert f"PB {t['dcs']['gain']:.3g} %" in action, action
        # issue 49: the CLI and the service give the same indices for the same window
        cli = subprocess.run(
            [*CLI, "diagnose", str(record), "--loop-type", "flow", "--json"],
            check=True, capture_output=True, text=True,
        )  # fmt: skip
        mine, stored = json.loads(cli.stdout)["kpis"], d["kpis"]
        assert stored["dead_time_source"] == "identified" and stored["harris_index"] is not None
        for key in ("error_mean", "error_std", "op_travel_per_day", "op_reversals_per_day",
                    "harris_index", "dead_time_s", "service_factor"):  # fmt: skip
            want = mine[key] if mine[key] is None else pytest.approx(mine[key], rel=0.02, abs=1e-3)
            assert stored[key] == want, (key, mine, stored)
        dom = dump_dom(f"{svc.url}/loop/TIC9", tmp_path / "profile")
        for chart in ("retune-sp", "retune-load", "retune-margins"):
            assert re.search(rf'id="{chart}"[^>]*data-rendered="true"', dom) or re.search(
                rf'data-rendered="true"[^>]*id="{chart}"', dom
            ), dom[:3000]
        assert 'id="proposed"' in dom and "proportional band" in dom
    finally:
        svc.stop()

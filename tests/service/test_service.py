"""The service end to end over real parts: ``plantcheck run`` (a new process) on a SQLite store
filled with simulated loop records, its scheduler, the REST API over HTTP, the web page in
headless Chromium."""

from __future__ import annotations

import csv
import io
import re
import subprocess
import time
from datetime import datetime, timedelta
from pathlib import Path

import httpx
import pytest
from helpers import RunCli, free_port
from servicehelpers import API_KEY, CLI, Service, dump_dom, start_service, write_config

from plantcheck.storage.database import upgrade


def test_every_loop_gets_its_true_cause(service: Service) -> None:
    loops = {lp["id"]: lp for lp in httpx.get(f"{service.url}/api/v1/loops").json()}
    assert set(loops) == set(service.truth)
    for name, truth in service.truth.items():
        lp = loops[name]
        assert lp["cause"] == truth["cause"], (name, lp)
        assert lp["since"].endswith("Z") and lp["last_diagnosis_at"].endswith("Z")
        if truth["S"] is not None:  # sticky valves: S estimated within 1 % of travel
            assert lp["S"] is not None and abs(lp["S"] - truth["S"]) < 1.0, (name, lp)
    states = {lp["id"]: lp["state"] for lp in loops.values()}
    assert states["FIC101"] == "ok" and states["FIC102"] == "fault"
    assert states["TIC401"] == "warning"


def test_loop_detail_and_history(service: Service) -> None:
    d = httpx.get(f"{service.url}/api/v1/loops/FIC102").json()
    assert d["diagnosis"]["schema"] == "plantcheck.diagnosis/1"
    assert d["diagnosis"]["cause"] == "stiction"
    r = httpx.get(f"{service.url}/api/v1/loops/FIC102/diagnoses", params={"limit": 1})
    assert r.status_code == 200 and len(r.json()) == 1
    assert int(r.headers["X-Total-Count"]) >= 1
    if int(r.headers["X-Total-Count"]) > 1:
        assert 'rel="next"' in r.headers["Link"]
        # the next-page link is relative: never built from the Host header (issue 27)
        forged = httpx.get(
            f"{service.url}/api/v1/loops/FIC102/diagnoses",
            params={"limit": 1},
            headers={"Host": "evil.example"},
        )
        assert forged.headers["Link"].startswith("</api/v1/loops/FIC102/diagnoses?")
    old = httpx.get(
        f"{service.url}/api/v1/loops/FIC102/diagnoses", params={"to": "2000-01-01T00:00:00Z"}
    )
    assert old.status_code == 200 and old.json() == []


def test_samples_in_a_time_range(service: Service) -> None:
    t0 = service.start + timedelta(minutes=10)
    r = httpx.get(
        f"{service.url}/api/v1/loops/FIC101/samples",
        params={
            "from": t0.isoformat(),
            "to": (t0 + timedelta(minutes=1)).replace(tzinfo=None).isoformat(),  # no zone: UTC
            "signal": "pv",
        },
    )
    assert r.status_code == 200
    rows = r.json()
    assert len(rows) == 60
    assert rows[0]["time"] == t0.strftime("%Y-%m-%dT%H:%M:%S.000Z") and rows[0]["signal"] == "pv"
    assert all(isinstance(x["value"], float) for x in rows)


def test_actions_and_stiction_report(service: Service) -> None:
    acts = httpx.get(f"{service.url}/api/v1/actions").json()
    by_loop = {a["loop"]: a for a in acts}
    assert by_loop["FIC102"]["code"] == "valve_maintenance" and by_loop["FIC102"]["priority"] == 1
    assert "FIC101" not in by_loop  # healthy: no action
    assert [a["priority"] for a in acts] == sorted(a["priority"] for a in acts)
    rep = httpx.get(f"{service.url}/api/v1/reports/stiction").json()
    valves = {v["loop"]: v for v in rep["valves"]}
    assert {"FIC102", "LIC201"} <= set(valves)
    assert valves["FIC102"]["limit"] == 2.0 and valves["FIC102"]["above_limit"] is True
    assert valves["FIC102"]["estimates"][0]["source"] == "op_pv"
    text = httpx.get(f"{service.url}/api/v1/reports/stiction", params={"format": "csv"}).text
    rows = list(csv.DictReader(io.StringIO(text)))
    assert rows and {r["loop"] for r in rows} >= {"FIC102", "LIC201"}


def test_probes_and_metrics(service: Service) -> None:
    assert httpx.get(f"{service.url}/healthz").json()["status"] == "ok"
    ready = httpx.get(f"{service.url}/readyz").json()
    # the source is down (nobody serves it) but within its grace period (a day here)
    assert ready == {
        "ready": True, "storage": True, "scheduler": True, "sources": True, "sources_down": [],
        "role": "single",  # SQLite: one process does everything
        "storage_writes": True, "buffer": True, "problems": [],
    }  # fmt: skip
    text = httpx.get(f"{service.url}/metrics").text
    for name in (
        "plantcheck_samples_per_second",
        "plantcheck_buffer_depth",
        "plantcheck_diagnosis_duration_seconds_count",
        'plantcheck_loops{state="fault"}',
        'plantcheck_loop_state{loop="FIC102",state="fault"} 1.0',
        'plantcheck_source_up{protocol="opcua",source="sim-opcua"} 0.0',
        "plantcheck_store_up 1.0",
        "plantcheck_store_failures_total 0.0",
        "plantcheck_scheduler_leader 1.0",  # the one SQLite process schedules
        "plantcheck_buffer_depth 0.0",  # the store keeps up: nothing waits
        "plantcheck_buffer_up 1.0",
        "plantcheck_samples_dropped_total 0.0",
    ):
        assert name in text
    assert re.search(r'plantcheck_loops\{state="fault"\} [1-9]', text)


def test_sources_show_the_one_nobody_serves_as_down(service: Service, tmp_path: Path) -> None:
    (src,) = httpx.get(f"{service.url}/api/v1/sources").json()
    assert src["name"] == "sim-opcua" and src["protocol"] == "opcua"
    assert src["state"] == "down" and src["since"].endswith("Z"), src
    assert src["failures"] >= 1 and src["last_error"] and src["last_good_sample_at"] is None
    # every page says so in a banner: the verdicts are not being refreshed
    dom = dump_dom(f"{service.url}/actions", tmp_path / "profile")
    assert 'id="sources-down"' in dom and "sim-opcua" in dom


def test_readyz_not_ready_once_a_source_is_down_past_its_grace(tmp_path: Path) -> None:
    port = free_port()
    config = write_config(tmp_path, port=port, down_grace_s=1.0)
    upgrade(f"sqlite+aiosqlite:///{tmp_path / 'plant.db'}")
    with (tmp_path / "run.log").open("wb") as err:
        proc = subprocess.Popen([*CLI, "run", "--config", str(config)], stderr=err)
    try:
        body = None
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                r = httpx.get(f"http://127.0.0.1:{port}/readyz", timeout=2)
                if r.status_code == 503:
                    body = r.json()
                    break
            except httpx.TransportError:
                pass
            time.sleep(0.3)
        assert body is not None, (tmp_path / "run.log").read_text(errors="replace")[-2000:]
        assert body["sources"] is False and body["sources_down"] == ["sim-opcua"], body
        assert body["storage"] and body["scheduler"]
    finally:
        proc.terminate()
        proc.wait(20)


@pytest.mark.parametrize(
    ("path", "params", "param"),
    [
        ("/api/v1/loops", {"limit": "0"}, "limit"),
        ("/api/v1/loops", {"state": "broken"}, "state"),
        ("/api/v1/loops", {"offset": "-1"}, "offset"),
        ("/api/v1/loops/FIC101/diagnoses", {"from": "yesterday"}, "from"),
        ("/api/v1/loops/FIC101/samples", {"signal": "xx"}, "signal"),
        ("/api/v1/reports/stiction", {"format": "xml"}, "format"),
        (
            "/api/v1/loops/FIC101/diagnoses",
            {"from": "2026-03-03T00:00:00Z", "to": "2026-03-02T00:00:00Z"},
            "from",
        ),
    ],
)
def test_bad_query_parameters_are_422_naming_the_parameter(
    service: Service, path: str, params: dict[str, str], param: str
) -> None:
    r = httpx.get(service.url + path, params=params)
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert any(param in d["loc"] for d in detail), detail


def test_unknown_loop_is_404(service: Service) -> None:
    for path in (
        "/api/v1/loops/NOPE",
        "/api/v1/loops/NOPE/diagnoses",
        "/api/v1/loops/NOPE/samples",
    ):
        r = httpx.get(service.url + path)
        assert r.status_code == 404 and "NOPE" in r.json()["detail"]


def test_changing_anything_needs_the_api_key(service: Service) -> None:
    url = f"{service.url}/api/v1/loops/FIC101/diagnose"
    assert httpx.post(url).status_code == 401
    assert httpx.post(url, headers={"X-API-Key": "wrong"}).status_code == 401
    r = httpx.post(url, headers={"X-API-Key": API_KEY}, timeout=60)
    assert r.status_code == 200 and r.json() == {"loop": "FIC101", "cause": "ok"}


def test_reads_need_the_key_when_configured(service: Service) -> None:
    port = free_port()
    folder = service.config.parent
    config = write_config(folder, port=port, reads_need_key=True)
    svc = start_service(config, port, service.truth, service.start)
    try:
        assert httpx.get(f"{svc.url}/api/v1/loops").status_code == 401
        # an empty key header never matches (issue 27)
        assert httpx.get(f"{svc.url}/api/v1/loops", headers={"X-API-Key": ""}).status_code == 401
        assert httpx.get(f"{svc.url}/").status_code == 401
        r = httpx.get(f"{svc.url}/api/v1/loops", headers={"X-API-Key": API_KEY})
        assert r.status_code == 200 and len(r.json()) == 11
        assert httpx.get(f"{svc.url}/healthz").status_code == 200  # probes stay open
    finally:
        svc.stop()


def test_bad_config_refused_with_line_and_key(tmp_path: Path, run_cli: RunCli) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text('[api]\nport = "eighty"\n', encoding="utf-8")
    r = run_cli("run", "--config", str(cfg))
    assert r.returncode == 2
    assert "bad.toml:2: api.port" in r.stderr


def test_unmigrated_database_refused_with_the_fix(tmp_path: Path, run_cli: RunCli) -> None:
    cfg = tmp_path / "plantcheck.toml"
    cfg.write_text(
        f'[storage]\nurl = "sqlite+aiosqlite:///{tmp_path / "x.db"}"\n'
        f'buffer_path = "{tmp_path / "b.db"}"\n',
        encoding="utf-8",
    )
    r = run_cli("run", "--config", str(cfg))
    # the fix names the file once (issue 47: "db upgrade --config  --config FILE")
    assert r.returncode == 2 and f"plantcheck db upgrade --config {cfg}`" in r.stderr, r.stderr


@pytest.mark.parametrize("command", ["run", "ingest"])
def test_storage_that_cannot_be_opened_is_refused_with_the_key(
    tmp_path: Path, run_cli: RunCli, command: str
) -> None:
    """An unwritable buffer path or a database nobody serves: exit 2 and the key to fix, never
    a traceback (issue 27)."""
    db = f"sqlite+aiosqlite:///{tmp_path / 'x.db'}"
    assert run_cli("db", "upgrade", "--config", str(_storage_config(tmp_path, db))).returncode == 0
    cfg = _storage_config(tmp_path, db, buffer="/proc/no-such-folder/buffer.db")
    extra = ["--duration", "1s"] if command == "ingest" else []
    r = run_cli(command, "--config", str(cfg), *extra)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "storage.buffer_path: cannot open the durable buffer" in r.stderr
    nobody = f"postgresql+asyncpg://u:p@127.0.0.1:{free_port()}/plant"
    r = run_cli(command, "--config", str(_storage_config(tmp_path, nobody)), *extra)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "cannot reach the database" in r.stderr and "check storage.url" in r.stderr


def _storage_config(folder: Path, url: str, buffer: str | None = None) -> Path:
    cfg = folder / "storage.toml"
    cfg.write_text(
        f'[storage]\nurl = "{url}"\nbuffer_path = "{buffer or folder / "buf.db"}"\n'
        f"[api]\nport = {free_port()}\n",
        encoding="utf-8",
    )
    return cfg


# -- the web page, in a real browser --------------------------------------------------------


def test_page_shows_the_health_table_sorted_and_coloured(service: Service, tmp_path: Path) -> None:
    dom = dump_dom(f"{service.url}/#sort=-S", tmp_path / "profile")
    rows = re.findall(r'<tr class="state-(\w+)" data-loop="(\w+)"', dom)
    assert len(rows) == 11
    by_loop = dict((name, state) for state, name in rows)
    assert by_loop["FIC102"] == "fault" and by_loop["FIC101"] == "ok"
    # sorted by S, largest first (by the page's script): the sticky valves lead
    assert {rows[0][1], rows[1][1], rows[2][1]} == {"FIC102", "LIC201", "FIC801"}
    assert 'aria-sort="descending"' in dom


def test_page_draws_the_loop_plots(service: Service, tmp_path: Path) -> None:
    dom = dump_dom(f"{service.url}/loop/FIC102", tmp_path / "profile")
    assert re.search(r'id="trend-pv"[^>]*data-rendered="true"', dom), dom[:2000]
    assert re.search(r'id="trend-op"[^>]*data-rendered="true"', dom)
    assert re.search(r'<canvas id="pvop"[^>]*data-rendered="true"', dom)
    assert "<canvas" in dom.split('id="trend-pv"', 1)[1]  # uPlot drew into a canvas
    assert "Schedule valve maintenance" in dom


def test_page_actions_and_stiction_report(service: Service, tmp_path: Path) -> None:
    dom = dump_dom(f"{service.url}/actions", tmp_path / "p1")
    assert "valve_maintenance" not in dom and "Schedule valve maintenance" in dom
    dom = dump_dom(f"{service.url}/stiction", tmp_path / "p2")
    assert re.search(r'data-loop="FIC102"[^>]*data-rendered="true"', dom) or re.search(
        r'data-rendered="true"[^>]*data-loop="FIC102"', dom
    )


def test_port_in_use_refused_with_the_fix(tmp_path: Path, run_cli: RunCli) -> None:
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cfg = tmp_path / "plantcheck.toml"
        db = tmp_path / "x.db"
        cfg.write_text(
            f'[storage]\nurl = "sqlite+aiosqlite:///{db}"\nbuffer_path = "{tmp_path / "b.db"}"\n'
            f"[api]\nport = {port}\n",
            encoding="utf-8",
        )
        r = run_cli("run", "--config", str(cfg), "--migrate")
        assert r.returncode == 2
        assert f"127.0.0.1:{port}" in r.stderr and "--port" in r.stderr


def test_docs_render_without_internet_and_links_ignore_the_host(
    service: Service, tmp_path: Path
) -> None:
    """Issue 47: /docs was blank without internet (Swagger UI from a CDN), and the pages built
    their links from the request's Host header."""
    dom = dump_dom(f"{service.url}/docs", tmp_path / "profile", offline=True)
    assert 'class="opblock' in dom and "/api/v1/loops" in dom, dom[-2000:]
    for path in ("/", "/docs", "/loop/FIC101", "/actions", "/stiction"):
        page = httpx.get(f"{service.url}{path}", headers={"Host": "cpm.plant.example"}).text
        assert "cpm.plant.example" not in page, path


def test_one_truth_per_loop_on_every_page(service: Service) -> None:
    """Issue 47: the table said S 3.00 where the loop page said "detected, not quantified", the
    loop and actions pages gave different action texts, and their "since" differed."""
    from markupsafe import escape

    loops = {lp["id"]: lp for lp in httpx.get(f"{service.url}/api/v1/loops").json()}
    acts = {a["loop"]: a for a in httpx.get(f"{service.url}/api/v1/actions").json()}
    actions_page = httpx.get(f"{service.url}/actions").text
    assert acts
    for loop_id, act in acts.items():
        assert act["since"] == loops[loop_id]["since"], (loop_id, act, loops[loop_id])
        page = httpx.get(f"{service.url}/loop/{loop_id}").text
        text = str(escape(act["action"]))  # as the pages' templates escape it (' is &#39;)
        assert text in page and text in actions_page, (loop_id, text)
        S = loops[loop_id]["S"]
        if S is not None:
            assert f"S = {S:.2f} %" in page and "not quantified" not in page, loop_id
        assert not re.search(r"period \d+\.\d{2,} s|amplitude \d+\.\d{3,}", page), loop_id
    # the maintenance report shows the table's S, its method and age, and the action's text
    report = httpx.get(f"{service.url}/api/v1/reports/stiction").json()
    report_page = httpx.get(f"{service.url}/stiction").text
    assert report["valves"]
    for v in report["valves"]:
        lp = loops[v["loop"]]
        assert (v["latest_S"], v["latest_J"], v["latest_method"], v["latest_at"]) == (
            lp["S"],
            lp["J"],
            lp["S_method"],
            lp["S_at"],
        ), (v, lp)
        assert v["action"] == (acts[v["loop"]]["action"] if v["loop"] in acts else None)
        if lp["S"] is not None:
            assert lp["S_at"] and lp["S_at"].endswith("Z"), lp
            written = f"S = {lp['S']:.2f} %"
            assert written in report_page and lp["S_at"] in report_page, v["loop"]
            assert written in httpx.get(f"{service.url}/loop/{v['loop']}").text
        if v["action"]:
            assert str(escape(v["action"])) in report_page, v["loop"]


def test_charts_are_in_utc_whatever_the_browser_zone(service: Service, tmp_path: Path) -> None:
    """Issue 47: the tables said UTC and the charts drew the browser's local 12-hour time."""
    detail = httpx.get(f"{service.url}/api/v1/loops/FIC101").json()
    start = datetime.fromisoformat(detail["window_start"].replace("Z", "+00:00"))
    end = datetime.fromisoformat(detail["window_end"].replace("Z", "+00:00"))
    hours = {
        f"{(start + timedelta(hours=h)).hour:02d}:"
        for h in range(int((end - start).total_seconds() // 3600) + 2)
    }
    dom = dump_dom(f"{service.url}/loop/FIC101", tmp_path / "profile", tz="Asia/Kolkata")
    m = re.search(r'id="trend-pv"[^>]*data-x-labels="([^"]*)"', dom) or re.search(
        r'data-x-labels="([^"]*)"[^>]*id="trend-pv"', dom
    )
    assert m, dom[:3000]
    labels = [x for x in m.group(1).split("|") if x]
    assert labels and not any(re.search(r"am|pm", x, re.I) for x in labels), labels
    assert any(x.strip()[:3] in hours or x.strip()[-5:-2] in hours for x in labels), (labels, hours)


def test_the_loop_table_is_as_fresh_as_the_diagnoses(service: Service) -> None:
    """Issue 47: polled every 10 s, GET /loops answered with the table of the previous poll.
    A diagnosis listed by /diagnoses before a /loops request is in that request's answer."""
    httpx.get(f"{service.url}/api/v1/loops")  # the poller's previous visit
    for _ in range(1):
        time.sleep(10.0)  # a 10-s poller
        newest = {
            loop_id: httpx.get(
                f"{service.url}/api/v1/loops/{loop_id}/diagnoses", params={"limit": 1}
            ).json()[0]["created_at"]
            for loop_id in ("FIC101", "FIC102")
        }
        table = {lp["id"]: lp for lp in httpx.get(f"{service.url}/api/v1/loops").json()}
        for loop_id, created in newest.items():
            assert table[loop_id]["last_diagnosis_at"] >= created, (loop_id, table[loop_id])

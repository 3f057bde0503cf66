"""The command line as a user runs it: help, version, JSON contracts, long records."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
from helpers import RunCli, free_port, modules_loaded

from plantcheck.diagnosis.result import CAUSES

EXAMPLE = Path(__file__).resolve().parents[2] / "simulator" / "examples" / "sticky_flow.csv"
DIAG_KEYS = {
    "schema", "loop_type", "chain", "samples", "sample_time_s", "cause", "confidence",
    "oscillating", "oscillation", "stiction", "valve", "indices", "actions", "notes",
}  # fmt: skip


def test_version_and_help(run_cli: RunCli) -> None:
    v = run_cli("--version")
    assert v.returncode == 0 and v.stdout.startswith("plantcheck ")
    for cmd in ([], ["diagnose"], ["oscillation"]):
        h = run_cli(*cmd, "--help")
        assert h.returncode == 0 and "Usage" in h.stdout


def test_diagnose_of_one_record_imports_only_what_it_needs(tmp_path: Path) -> None:
    """Issue 46's start-up budget (0.7 s for ``diagnose`` of 3,600 samples, a record that gets
    no S/J estimate): typer 0.29 imports pydantic to convert parameters (0.2-0.3 s and 10 MB on
    a slow machine), hence its pin below 0.29; ``importlib.metadata`` (the version), asyncio
    and click were 20-50, 25 and 10 ms, ``numpy.ma`` (``np.median``'s and ``np.unique``'s
    first call) 6-17 ms, the S/J quantification (a record it does not size) 20 ms; the service's
    stack has no business in a one-record diagnosis."""
    import subprocess
    import sys

    rng = np.random.default_rng(1)
    k = np.arange(3600)
    pv = 50 + np.sign(np.sin(2 * np.pi * k / 120)) + 0.1 * rng.normal(size=k.size)
    op = 40 + 3 * np.sin(2 * np.pi * k / 120 - 1) + 0.2 * rng.normal(size=k.size)
    rec = tmp_path / "loop.csv"
    rec.write_text("t,sp,pv,op\n" + "".join(f"{t},50,{a:.3f},{b:.3f}\n" for t, a, b in
                                            zip(k, pv, op, strict=True)))  # fmt: skip
    heavy = ("pydantic", "fastapi", "sqlalchemy", "asyncua", "pymodbus", "lightgbm", "scipy",
             "asyncio", "click", "importlib.metadata", "numpy.ma",
             "plantcheck.diagnosis.quantification")  # fmt: skip
    code = (
        "import sys\n"
        "from plantcheck.service.cli import main\n"
        f"sys.argv = ['plantcheck', 'diagnose', {str(rec)!r}, '--json']\n"
        "try:\n    main()\nexcept SystemExit as exit:\n    assert not exit.code, exit.code\n"
        f"heavy = {heavy!r}\n"
        "print(sorted(m for m in sys.modules if m in heavy or m.split('.')[0] in heavy),"
        " file=sys.stderr)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout)["stiction"]["S"] is None
    assert out.stderr.strip() == "[]", out.stderr


def test_the_record_reader_loads_no_chain() -> None:
    """``plantcheck import`` reads records and diagnoses nothing: the reader's median comes
    from ``diagnosis.signal_tools``, and the package loads its entry points only when asked
    (every one of them still resolves)."""
    import plantcheck.diagnosis as d

    loaded = modules_loaded("plantcheck.service.records", ("plantcheck.diagnosis.",))
    assert loaded == ["plantcheck.diagnosis.signal_tools"]
    assert all(getattr(d, name) is not None for name in d.__all__)


def test_demo_refuses_a_bad_admin_address_before_it_starts(run_cli: RunCli) -> None:
    """``demo --admin`` (issue 48: a proposal typed into the simulator) names the option and
    the fix for an address it cannot use, and starts nothing (no port, no database)."""
    import socket

    bad = run_cli("demo", "--admin", "nowhere", "--port", str(free_port()))
    assert bad.returncode != 0 and "--admin" in bad.stderr and "off" in bad.stderr, bad.stderr
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        busy = run_cli("demo", "--admin", f"127.0.0.1:{port}", "--port", str(free_port()))
    assert busy.returncode != 0 and "choose another with --admin" in busy.stderr, busy.stderr


def test_demo_names_a_data_dir_it_cannot_write(run_cli: RunCli, tmp_path: Path) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    r = run_cli("demo", "--data-dir", str(a_file / "demo"), "--port", str(free_port()))
    assert r.returncode == 2 and "plantcheck: error: --data-dir " in r.stderr, r.stderr
    assert "internal error" not in r.stderr


def test_help_says_it_whole_and_every_reference_resolves(run_cli: RunCli) -> None:
    """Issue 47: summaries cut off with "...", no default shown for --speed, "about 2 minutes"
    where the README says one, and "contracts §2" that no file in the repository holds."""
    import re

    top = run_cli("--help").stdout
    assert "..." not in top.split("Commands:")[1], top
    sim_help = " ".join(run_cli("simulate", "--help").stdout.split())
    assert "clock.speed (1 in the bundled scenario)" in sim_help, sim_help
    assert "about a minute" in " ".join(run_cli("demo", "--help").stdout.split())
    root = Path(__file__).resolve().parents[2]
    contracts = (root / "docs" / "contracts.md").read_text(encoding="utf-8")
    sections = set(re.findall(r"^## (\d+)\.", contracts, re.M))
    texts = [(root / "README.md").read_text(encoding="utf-8")]
    texts += [f.read_text(encoding="utf-8") for f in (root / "service").glob("cli*.py")]
    cited = {n for t in texts for n in re.findall(r"contracts(?:\.md)? §(\d+)", t)}
    assert cited and cited <= sections, (cited, sections)
    assert not any(re.search(r"(?<![/\w.])contracts §", t) for t in texts)


def test_diagnose_json_contract(run_cli: RunCli) -> None:
    proc = run_cli("diagnose", str(EXAMPLE), "--loop-type", "flow", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert set(out) >= DIAG_KEYS
    assert out["schema"] == "plantcheck.diagnosis/1"
    assert out["chain"] == "standard" and out["valve"] is None
    assert out["cause"] in CAUSES and out["cause"] == "stiction"
    assert out["loop_type"] == "flow" and out["samples"] == 3600 and out["sample_time_s"] == 1.0
    assert set(out["oscillation"]) == {"period_s", "amplitude", "regularity"}
    # the bundled record was simulated with a Kano valve, S = 3 %, J = 1 %
    assert abs(out["stiction"]["S"] - 3.0) < 0.3 and abs(out["stiction"]["J"] - 1.0) < 0.5
    assert out["stiction"]["quantification"]["reliable"] is True
    assert out["stiction"]["tests"]["cross_correlation"] in ("odd", "even", "undecided")
    assert {"hagglund_load_count", "idle_index", "saturation_fraction"} <= set(out["indices"])
    assert out["actions"][0]["code"] == "valve_maintenance"
    assert "S = 3.0 %" in out["actions"][0]["text"]


def test_diagnose_summary_is_readable(run_cli: RunCli) -> None:
    proc = run_cli("diagnose", str(EXAMPLE))
    assert proc.returncode == 0
    assert "cause:" in proc.stdout and "action:" in proc.stdout


def test_oscillation_json_contract(run_cli: RunCli) -> None:
    proc = run_cli("oscillation", str(EXAMPLE), "--column", "OP", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["schema"] == "plantcheck.oscillation/1"
    assert out["column"] == "op" and out["oscillating"] is True
    assert 40 < out["period_s"] < 80
    assert {"amplitude", "regularity", "samples", "sample_time_s"} <= set(out)


def test_oscillation_bad_column(run_cli: RunCli, tmp_path: Path) -> None:
    proc = run_cli("oscillation", str(EXAMPLE), "--column", "flowrate")
    assert proc.returncode == 2 and "--column" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow(minutes=0.5)  # 20-30 s: started early, not last
def test_ten_million_rows(run_cli: RunCli, tmp_path: Path) -> None:
    """A 10-million-row file: diagnosed on its last --max-samples samples, never a traceback."""
    n = 10_000_000
    path = tmp_path / "big.csv"
    rng = np.random.default_rng(0)
    block = 100_000
    k = np.arange(block)
    pv = 50 + np.sin(2 * np.pi * k / 60) + 0.1 * rng.normal(size=block)
    op = 40 + np.cos(2 * np.pi * k / 60)
    # one block's rows with t's last five digits; each block prefixes its number to every t
    # (block 7's row 12 is t = 700012), so 10 M rows cost a bytes.replace per block, not a
    # formatting per row (12 s of the test before)
    rows = io.BytesIO()
    np.savetxt(rows, np.column_stack([k, pv, op]), fmt=["%05d", "%.3f", "%.3f"], delimiter=",")
    body = rows.getvalue()
    with path.open("wb") as f:
        f.write(b"t,pv,op\n")
        for b in range(n // block):
            prefix = str(b).encode() if b else b""
            f.write(prefix + body[:-1].replace(b"\n", b"\n" + prefix) + b"\n")
    proc = run_cli("diagnose", str(path), "--json")
    assert "Traceback" not in proc.stderr
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["samples"] == 200_000
    assert any("record has 10000000 rows: read the last 400000" in n for n in out["notes"])


def test_a_long_record_is_read_with_memory_bounded_by_max_rows(tmp_path: Path) -> None:
    """Only the last ``max_rows`` rows are kept while the file streams (issue 27)."""
    from plantcheck.service.records import read_record

    f = tmp_path / "long.csv"
    f.write_text("t,pv,op\n" + "".join(f"{k},{50 + k % 7},{40 + k % 5}\n" for k in range(5000)))
    rec = read_record(f, max_rows=1000)
    assert rec.t.size == 1000 and rec.get("pv") is not None
    assert "record has 5000 rows: read the last 1000" in rec.notes
    assert read_record(f).t.size == 5000


@pytest.mark.slow(minutes=0.5)  # 20-30 s: started early, not last
def test_model_fit_rebuilds_a_model_the_diagnosis_reads(run_cli: RunCli, tmp_path: Path) -> None:
    """Issue 46: one command rebuilds the model file from the simulated corpus (a small one
    here): the trees, checked against LightGBM's own scores inside the command, and the shape
    network."""
    from plantcheck.diagnosis.cause_model import load_cause_model
    from plantcheck.diagnosis.evidence import FEATURE_NAMES
    from plantcheck.service.shape_model_fit import EPOCHS

    out = tmp_path / "m.npz"
    r = run_cli("model", "fit", "--windows", "60", "--out", str(out), "--jobs", "2", "--json",
                "--tree-seed", "3", "--shape-seed", "2")  # fmt: skip
    assert r.returncode == 0, r.stderr
    figures = json.loads(r.stdout)
    assert figures["windows"]["fit"] >= 55 and 0.0 <= figures["check_macro_f1"] <= 1.0
    assert "corpus seed" in r.stderr  # progress on stderr
    model = load_cause_model(out)
    assert model.features == FEATURE_NAMES and model.meta["library"] == "lightgbm"
    assert model.meta["seeds"]["trees"] == 3 and model.meta["params"]["num_threads"] == 2
    # the shape network, blended in by the weight the calibration windows gave
    assert model.shape is not None and model.meta["shape"]["library"] == "torch"
    assert model.meta["shape"]["seed"] == 2
    # two networks, seeds 2 and 3, averaged
    assert len(model.shape_more) == 1 and model.meta["shape"]["networks"] == 2
    assert model.shape_weight == figures["shape_weight"] and 0.0 <= model.shape_weight <= 1.0
    assert f"shape network: epoch {EPOCHS}/{EPOCHS}" in r.stderr


def test_model_fit_refuses_an_unwritable_output_before_it_draws(
    run_cli: RunCli, tmp_path: Path
) -> None:
    """A path that cannot be written is named at once, not after the corpus' half-hour draw."""
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    for args, option in (
        (["--out", str(a_file / "m.npz")], "--out"),
        (["--out", str(tmp_path)], "--out"),
        (["--out", str(tmp_path / "m.npz"), "--cache", str(a_file / "cache")], "--cache"),
    ):
        r = run_cli("model", "fit", "--windows", "60", *args)
        assert r.returncode == 2 and f"plantcheck: error: {option} " in r.stderr, r.stderr
        assert "corpus seed" not in r.stderr and "Traceback" not in r.stderr


def test_simulate_names_an_output_path_it_cannot_write(run_cli: RunCli, tmp_path: Path) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    for args, option in (
        (["--to-csv", str(a_file), "--duration", "1m"], "--to-csv"),
        (["--to-csv", str(a_file / "records"), "--duration", "1m"], "--to-csv"),
        (["--export-map", str(a_file / "map.csv")], "--export-map"),
    ):
        r = run_cli("simulate", *args)
        assert r.returncode == 2 and f"plantcheck: error: {option} " in r.stderr, r.stderr
        assert "Traceback" not in r.stderr and "internal error" not in r.stderr


def test_model_fit_defaults_to_the_fit_modules_counts() -> None:
    """The CLI keeps its own copy of the default (importing the fit module would cost every
    command's start-up numpy and scipy): the two must agree."""
    import inspect

    from plantcheck.service.cause_model_fit import FIT_WINDOWS, SHAPE_NETWORKS
    from plantcheck.service.cli_model import fit_cmd

    defaults = inspect.signature(fit_cmd).parameters
    assert defaults["windows"].default == FIT_WINDOWS
    assert defaults["networks"].default == SHAPE_NETWORKS


def test_diagnose_decision_learned(run_cli: RunCli) -> None:
    r = run_cli("diagnose", str(EXAMPLE), "--loop-type", "flow", "--json", "--decision", "learned")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["cause"] == "stiction" and abs(sum(out["probabilities"].values()) - 1) < 0.01
    assert out["confidence"] == round(out["probabilities"]["stiction"], 2)
    bad = run_cli("diagnose", str(EXAMPLE), "--decision", "guess")
    assert bad.returncode == 2 and "--decision" in bad.stderr


def test_diagnose_with_a_baseline(run_cli: RunCli, tmp_path: Path) -> None:
    """Issue 46 item 5: ``--baseline FILE`` reads the loop's healthy variability from a record
    of it; a window whose error varies several times more is not ok."""
    from plantcheck.simulator.cases import simc_pi
    from plantcheck.simulator.loop import Disturbance, LoopConfig, Process, simulate_loop

    proc = Process("fopdt", K=1.0, tau_s=20.0, theta_s=5.0)

    def record(noise: float, seed: int, name: str) -> Path:
        load = (Disturbance(filtered_noise_std=0.3),)
        r = simulate_loop(LoopConfig(process=proc, controller=simc_pi(proc), noise_std=noise,
                                     n_samples=3000, disturbances=load, seed=seed))  # fmt: skip
        path = tmp_path / name
        rows = "\n".join(f"{t:g},{s:.4f},{p:.4f},{o:.4f}" for t, s, p, o in
                         zip(r.t, r.sp, r.pv, r.op, strict=True))  # fmt: skip
        path.write_text("t,sp,pv,op\n" + rows + "\n")
        return path

    normal, noisy = record(0.1, 1, "normal.csv"), record(0.8, 3, "noisy.csv")
    args = ("diagnose", str(noisy), "--loop-type", "temperature", "--json")
    plain = json.loads(run_cli(*args).stdout)
    assert plain["cause"] == "ok"
    r = run_cli(*args, "--baseline", str(normal))
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["cause"] == "performance_degraded" and out["indices"]["variability_ratio"] > 3
    # issue 49: the same ratio among the indices; a given dead time gives the Harris index
    assert out["kpis"]["variability_ratio"] == pytest.approx(
        out["indices"]["variability_ratio"], rel=0.02
    )
    assert out["kpis"]["harris_index"] is None and "dead_time_s" in out["kpis"]["harris_note"]
    timed = json.loads(run_cli(*args, "--dead-time", "5").stdout)["kpis"]
    assert 0 < timed["harris_index"] <= 1 and timed["dead_time_source"] == "configured"
    assert run_cli(*args, "--dead-time", "-1").returncode == 2
    assert any("normal.csv" in n for n in out["notes"])
    flat = tmp_path / "flat.csv"
    flat.write_text("t,pv,op\n" + "".join(f"{t},50,40\n" for t in range(200)))
    bad = run_cli(*args, "--baseline", str(flat))
    assert bad.returncode == 2 and "flat.csv" in bad.stderr and "normal operation" in bad.stderr


def test_diagnose_level_control_tight_retunes_a_level_as_tightly_as_any_loop(
    run_cli: RunCli, tmp_path: Path
) -> None:
    """Issue 48: a level loop's proposal is loose on purpose (averaging control, τc = 3θ at
    the model's cautious edge) unless ``--level-control tight`` says the level matters (τc =
    θ); a value it does not know is refused naming the option."""
    from plantcheck.simulator.tuning_cases import tuning_case

    r = tuning_case(11006, "sluggish", 0.3).record
    path = tmp_path / "lic.csv"
    rows = "\n".join(f"{t:g},{s:.4f},{p:.5f},{o:.4f}" for t, s, p, o in
                     zip(r.t, r.sp, r.pv, r.op, strict=True))  # fmt: skip
    path.write_text("t,sp,pv,op\n" + rows + "\n")
    args = ("diagnose", str(path), "--loop-type", "level", "--json")
    proposals = {}
    for mode in ("averaging", "tight"):
        out = run_cli(*args, "--level-control", mode)
        assert out.returncode == 0, out.stderr
        d = json.loads(out.stdout)
        assert d["cause"] == "sluggish_tuning", d["cause"]
        proposals[mode] = d["tuning"]["proposed"]
    loose, tight = proposals["averaging"], proposals["tight"]
    assert loose["tau_c_s"] == pytest.approx(3.0 * tight["tau_c_s"], rel=0.01)
    assert tight["Kc"] > 1.5 * loose["Kc"]
    bad = run_cli(*args, "--level-control", "average")
    assert bad.returncode == 2 and "--level-control" in bad.stderr

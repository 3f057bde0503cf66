"""The README's two set-up commands, in the order written, in a scratch clone (issue 29):
command 1 makes ``.venv`` with a plain ``pip install .`` and runs the demo; command 2,
``make test``, must then install the development tools into that same ``.venv`` and pass.

Tests reach no network: pip installs from a local wheelhouse repacked from this test's own
environment (every installed distribution, as the wheel it was installed from), with
``PIP_NO_INDEX``, and without compiling the installed modules to bytecode (``PIP_NO_COMPILE``,
which ``make venv`` honours too: the same files installed, 20 of the test's 118 CPU seconds
spared by pip and about 48 by the Makefile's compileall; Python compiles what it imports). The
demo runs 10 s on a free port; ``make test`` runs the linters, mypy and the tests of
``tests/core`` in one process (``PYTEST_ARGS``: the whole suite already runs around this test;
``-n 0`` spares starting four workers for one file).
"""

from __future__ import annotations

import base64
import csv
import hashlib
import io
import os
import re
import shutil
import subprocess
import sys
import zipfile
from importlib import metadata
from pathlib import Path

import pytest
from helpers import free_port

ROOT = Path(__file__).resolve().parents[1]
SKIPPED_FILES = ("INSTALLER", "REQUESTED", "direct_url.json", "RECORD")


def _readme_commands() -> tuple[str, str]:
    """The two commands of the README's set-up block (the lines that are not comments)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"## Set up.*?```sh\n(.*?)```", text, re.S)
    assert block, "README has no set-up block"
    lines = [ln for ln in block.group(1).splitlines() if ln.strip() and not ln.startswith("#")]
    assert len(lines) == 2, f"README's set-up block should hold two commands: {lines}"
    return lines[0], lines[1]


def _digest(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def _repack(dist: metadata.Distribution, into: Path) -> Path | None:
    """``dist`` as a wheel again (its files from RECORD, a fresh RECORD; scripts are left to
    pip, which writes them from entry_points.txt), or None when it cannot be."""
    files = dist.files
    info = dist.read_text("WHEEL")
    if not files or info is None:
        return None
    tags = [t.split("-") for t in re.findall(r"^Tag: (\S+)$", info, re.M)] or [
        ["py3", "none", "any"]
    ]
    # the compressed tag set of the file name: py2.py3-none-any
    tag = "-".join(".".join(dict.fromkeys(t[i] for t in tags)) for i in range(3))
    name = re.sub(r"[-_.]+", "_", dist.metadata["Name"])
    wheel = into / f"{name}-{dist.version}-{tag}.whl"
    prefix = Path(sys.prefix).resolve()
    scripts = prefix / "bin"
    entry_points = {ep.name for ep in dist.entry_points if ep.group.endswith("_scripts")}
    data_dir = f"{name}-{dist.version}.data"
    record = io.StringIO()
    writer = csv.writer(record, lineterminator="\n")
    dist_info = None
    with zipfile.ZipFile(wheel, "w", zipfile.ZIP_STORED) as zf:
        for f in files:
            rel = f.as_posix()
            if "__pycache__" in rel:
                continue
            path = Path(str(dist.locate_file(f))).resolve()
            if not path.is_file():
                continue
            data = path.read_bytes()
            if rel.startswith(".."):
                # outside site-packages: a script (bin/) or data under the prefix; console
                # scripts are left to pip, which writes them from entry_points.txt
                if path.parent == scripts and path.name not in entry_points:
                    if data.startswith(b"#!") and b"python" in data.split(b"\n", 1)[0]:
                        data = b"#!python\n" + data.split(b"\n", 1)[1]
                    rel = f"{data_dir}/scripts/{path.name}"
                elif path.is_relative_to(prefix) and path.parent != scripts:
                    rel = f"{data_dir}/data/{path.relative_to(prefix).as_posix()}"
                else:
                    continue
            elif rel.split("/")[0].endswith(".dist-info"):
                dist_info = rel.split("/")[0]
                if rel.split("/")[-1] in SKIPPED_FILES:
                    continue
            entry = zipfile.ZipInfo(rel)
            entry.external_attr = (path.stat().st_mode & 0xFFFF) << 16  # keeps the x bit
            zf.writestr(entry, data)
            writer.writerow([rel, _digest(data), len(data)])
        if dist_info is None:
            return None
        writer.writerow([f"{dist_info}/RECORD", "", ""])
        zf.writestr(f"{dist_info}/RECORD", record.getvalue())
    return wheel


def _wheelhouse(into: Path) -> None:
    """Every distribution installed in this environment but plantcheck, as a wheel."""
    into.mkdir()
    for dist in metadata.distributions():
        if dist.metadata["Name"].lower() != "plantcheck":
            _repack(dist, into)


@pytest.mark.slow(minutes=3)
def test_readme_commands_work_in_the_order_written(tmp_path: Path) -> None:
    if shutil.which("git") is None or shutil.which("make") is None:
        pytest.skip("needs git and make")
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: nothing to clone")
    first, second = _readme_commands()
    assert second.strip() == "make test"
    clone = tmp_path / "plantcheck"
    subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
    _wheelhouse(tmp_path / "wheels")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PIP_", "VIRTUAL_ENV"))}
    env |= {
        "PIP_NO_INDEX": "1",
        "PIP_FIND_LINKS": str(tmp_path / "wheels"),
        "PIP_DISABLE_PIP_VERSION_CHECK": "1",
        "PIP_NO_COMPILE": "1",
        "PATH": os.pathsep.join(
            p for p in env.get("PATH", "").split(os.pathsep) if not p.startswith(sys.prefix)
        ),
    }
    port = free_port()
    one = _run(["bash", "-c", f"{first} --port {port} --duration 10"], clone, env, "command 1")
    assert (clone / ".venv" / "bin" / "plantcheck").exists()
    assert f"http://127.0.0.1:{port}/" in one
    # mypy's cache from this checkout's own `make test` (mypy re-checks any file whose content
    # differs): a cold run is the largest share of command 2 that nothing else here tests
    if (ROOT / ".mypy_cache").is_dir():
        shutil.copytree(ROOT / ".mypy_cache", clone / ".mypy_cache")
    two = _run(["make", "test", "PYTEST_ARGS=-n 0 tests/core"], clone, env, "command 2")
    assert (clone / ".venv" / "bin" / "ruff").exists()
    assert " passed" in two


def _run(args: list[str], cwd: Path, env: dict[str, str], what: str) -> str:
    """Run one set-up command to its end (30 minutes at most); its output."""
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, f"{what} failed:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout + done.stderr

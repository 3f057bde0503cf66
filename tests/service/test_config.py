"""The service configuration: the README example validates, bad files are refused precisely."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from plantcheck.core.toml_config import ConfigError
from plantcheck.service.config import Config, load_config

ROOT = Path(__file__).resolve().parents[2]


def readme_config(tmp_path: Path, pattern: str) -> Config:
    """The README's TOML block matched by ``pattern`` (its first group), loaded."""
    block = re.search(pattern, (ROOT / "README.md").read_text(), re.S)
    assert block, f"README has no configuration block matching {pattern!r}"
    path = tmp_path / "plantcheck.toml"
    path.write_text(block.group(1))
    return load_config(path)


def test_readme_example_is_a_valid_configuration(tmp_path: Path) -> None:
    cfg = readme_config(tmp_path, r"```toml\n(\[storage\].*?)```")
    assert {s.protocol for s in cfg.source} == {"modbus", "opcua"}
    assert cfg.loop[0].tags()["pv"] == "hr:22:float32"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('[api]\nport = "x"\n', ":2: api.port: Input should be a valid integer"),
        (
            '[[source]]\nname = "a"\nprotocol = "modbus"\n[[loop]]\nid = "L"\nsource = "b"\n'
            'pv = "hr:1:float32"\nop = "hr:3:float32"\n',
            ":6: loop[0].source: unknown source 'b' (sources: a)",
        ),
        (
            '[[source]]\nname = "a"\nprotocol = "modbus"\n[[loop]]\nid = "L"\nsource = "a"\n'
            'pv = "holding:1"\nop = "hr:3:float32"\n',
            ":7: loop[0].pv: 'holding:1' is not a Modbus tag",
        ),
        ('[[source]]\nname = "u"\nprotocol = "opcua"\n', ": source[0]: Value error, source 'u'"),
        ("[storage]\nurl = 'mysql://x'\n", ":2: storage.url: Value error, expected sqlite"),
        ("[storage\n", ":1: syntax: not valid TOML"),
        (
            "[scheduler]\nwindow_cache_mb = -5\n",
            ":2: scheduler.window_cache_mb: Input should be greater than or equal to 0",
        ),
    ],
)
def test_bad_configuration_is_refused_with_line_and_key(
    tmp_path: Path, text: str, expected: str
) -> None:
    path = tmp_path / "plantcheck.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert expected in str(info.value), str(info.value)


def test_deploy_example_is_a_valid_configuration() -> None:
    cfg = load_config(ROOT / "deploy" / "plantcheck.example.toml")
    assert cfg.storage.url.startswith("postgresql+asyncpg://")
    assert cfg.loop[0].stiction_limit == 2.0


def test_readme_service_keys_are_valid_configuration(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PLANTCHECK_UNIT1_PASSWORD", "pw")
    cfg = readme_config(tmp_path, r"```toml\n(\[api\].*?)\[\[loop\]\]")
    assert cfg.scheduler.confirm == 2 and cfg.scheduler.quantify_every_s == 3600
    assert cfg.scheduler.window_cache_mb == 256 and cfg.scheduler.engine == "local"
    assert cfg.source[0].collector == "unit1"
    assert cfg.source[0].password.get_secret_value() == "pw"


def test_opcua_password_comes_from_the_environment_or_a_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PLANTCHECK_TEST_PW", "from-env")
    (tmp_path / "pw").write_text("from-file\n", encoding="utf-8")
    source = (
        '[[source]]\nname = "{n}"\nprotocol = "opcua"\nurl = "opc.tcp://10.0.0.5:4840/"\n'
        'security_policy = "Basic256Sha256"\nusername = "plantcheck"\n{k} = "{v}"\n'
    )
    path = tmp_path / "plantcheck.toml"
    path.write_text(
        source.format(n="a", k="password_env", v="PLANTCHECK_TEST_PW")
        + source.format(n="b", k="password_file", v=tmp_path / "pw"),
        encoding="utf-8",
    )
    cfg = load_config(path)
    assert [s.password.get_secret_value() for s in cfg.source] == ["from-env", "from-file"]
    assert "from-env" not in repr(cfg) and "from-file" not in repr(cfg)  # SecretStr


def test_api_key_comes_from_a_file(tmp_path: Path) -> None:
    (tmp_path / "key").write_text("k-123\n", encoding="utf-8")
    path = tmp_path / "plantcheck.toml"
    path.write_text(f'[api]\napi_key_file = "{tmp_path / "key"}"\n', encoding="utf-8")
    cfg = load_config(path)
    assert cfg.api.api_key == "k-123" and "k-123" not in repr(cfg)


def test_deploy_site_example_is_a_valid_configuration(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PLANTCHECK_API_KEY", "k")
    monkeypatch.setenv("PLANTCHECK_UNIT1_OPCUA_PASSWORD", "p")
    cfg = load_config(ROOT / "deploy" / "site.example.toml")
    assert cfg.scheduler.engine == "queue" and cfg.collectors() == ["unit1", "unit2"]
    assert [lp.id for lp in cfg.read_by("unit1").loop] == ["10-FIC-101"]
    assert cfg.read_by("").source == []  # the service machine reads no source itself


def test_a_level_loops_control_goal_reaches_its_retuning(tmp_path: Path) -> None:
    """Issue 48: ``controller.level_control`` goes with the loop's schedule to the retuning
    (averaging unless configured), apart from the controller's form."""
    from plantcheck.service.runtime import schedules_of
    from plantcheck.service.window_diagnosis import _retuning

    path = tmp_path / "plantcheck.toml"
    path.write_text(
        '[[source]]\nname = "plc"\nprotocol = "modbus"\n\n'
        '[[loop]]\nid = "LIC1"\ntype = "level"\nsource = "plc"\n'
        'pv = "hr:1:float32"\nop = "hr:3:float32"\n'
        'controller = { level_control = "tight", integral = "minutes" }\n\n'
        '[[loop]]\nid = "LIC2"\ntype = "level"\nsource = "plc"\n'
        'pv = "hr:5:float32"\nop = "hr:7:float32"\n'
    )
    tight, default = (_retuning(dict(s.controller)) for s in schedules_of(load_config(path)))
    assert tight.retune.level_control == "tight" and tight.form.integral == "minutes"
    assert default.retune.level_control == "averaging" and default.form.integral == "seconds"

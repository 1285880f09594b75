"""Config loading: merge order and the error messages users see for bad input."""

from __future__ import annotations

from pathlib import Path

import pytest

from physanim.config import ConfigError, load_config, parse_override
from tests.foundation.toy_stages import ScaleParams, SourceParams, toy_pipeline


@pytest.fixture
def model(toy_config: Path):
    return toy_pipeline(toy_config).config_model()


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_merge_order_files_then_overrides(model, toy_config: Path, tmp_path: Path) -> None:
    extra = write(tmp_path, "extra.yaml", "scale:\n  factor: 4.0\n")
    cfg, origins = load_config(model, [toy_config, extra])
    assert cfg.scale.factor == 4.0 and cfg.source.n_frames == 8
    assert origins["scale.factor"] == str(extra)
    cfg, origins = load_config(model, [toy_config, extra], ["scale.factor=6"])
    assert cfg.scale.factor == 6.0 and origins["scale.factor"] == "--set scale.factor=6"


def test_section_is_typed_and_names_a_mismatch(model, toy_config: Path) -> None:
    cfg, _ = load_config(model, [toy_config], ["scale.factor=6"])
    assert cfg.section("scale", ScaleParams).factor == 6.0
    with pytest.raises(TypeError, match="'scale' is ScaleParams, not SourceParams"):
        cfg.section("scale", SourceParams)
    with pytest.raises(TypeError, match="'demo' is NoneType, not ScaleParams"):
        cfg.section("demo", ScaleParams)


def test_unknown_key_names_file_key_and_allowed(model, toy_config, tmp_path) -> None:
    bad = write(tmp_path, "bad.yaml", "scale:\n  facter: 4.0\n")
    with pytest.raises(ConfigError) as exc:
        load_config(model, [toy_config, bad])
    msg = str(exc.value)
    assert f"{bad}: scale.facter: unknown key; allowed keys here: factor" in msg


def test_unknown_section_lists_sections(model, toy_config, tmp_path) -> None:
    bad = write(tmp_path, "bad.yaml", "simulat:\n  dt: 0.001\n")
    with pytest.raises(ConfigError, match=r"simulat: unknown key; allowed keys here: dataset, "):
        load_config(model, [toy_config, bad])


def test_wrong_type(model, toy_config, tmp_path) -> None:
    bad = write(tmp_path, "bad.yaml", "source:\n  n_frames: lots\n")
    with pytest.raises(ConfigError) as exc:
        load_config(model, [toy_config, bad])
    assert f"{bad}: source.n_frames: Input should be a valid integer" in str(exc.value)
    assert "(got 'lots')" in str(exc.value)


def test_out_of_range_names_the_bound(model, toy_config, tmp_path) -> None:
    bad = write(tmp_path, "bad.yaml", "scale:\n  factor: 500\n")
    with pytest.raises(ConfigError) as exc:
        load_config(model, [toy_config, bad])
    assert f"{bad}: scale.factor: must be <= 100.0 (got 500)" in str(exc.value)
    with pytest.raises(ConfigError, match=r"--set scale.factor=0: scale.factor: must be > 0.0"):
        load_config(model, [toy_config], ["scale.factor=0"])


def test_missing_file_and_bad_yaml(model, toy_config, tmp_path) -> None:
    with pytest.raises(ConfigError, match=r"nope.yaml: config file not found"):
        load_config(model, [toy_config, tmp_path / "nope.yaml"])
    bad = write(tmp_path, "bad.yaml", "scale: [1, 2\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: not valid YAML"):
        load_config(model, [toy_config, bad])
    bad = write(tmp_path, "list.yaml", "- 1\n- 2\n")
    with pytest.raises(ConfigError, match=r"list.yaml: top level must be a mapping"):
        load_config(model, [toy_config, bad])


def test_override_syntax() -> None:
    assert parse_override("simulate.dt=1e-3") == {"simulate": {"dt": 1e-3}}
    assert parse_override("a.b.c=[1, 2]") == {"a": {"b": {"c": [1, 2]}}}
    with pytest.raises(ConfigError, match="expected dotted.key=value"):
        parse_override("simulate.dt")
    with pytest.raises(ConfigError, match="is not a dotted key"):
        parse_override("simulate..dt=1")


def test_include_merges_first_and_detects_cycles(model, toy_config, tmp_path) -> None:
    write(tmp_path, "base.yaml", "scale:\n  factor: 3.0\nsource:\n  n_frames: 5\n")
    top = write(tmp_path, "top.yaml", "include: base.yaml\nscale:\n  factor: 4.0\n")
    cfg, origins = load_config(model, [toy_config, top])
    assert (cfg.scale.factor, cfg.source.n_frames) == (4.0, 5)
    assert origins["source.n_frames"] == str((tmp_path / "base.yaml").resolve())
    write(tmp_path, "a.yaml", "include: b.yaml\n")
    write(tmp_path, "b.yaml", "include: a.yaml\n")
    with pytest.raises(ConfigError, match="include cycle"):
        load_config(model, [toy_config, tmp_path / "a.yaml"])

"""Every YAML file under configs/ loads and validates as what it is, and a single nested value
given by ``--set`` or a sweep grid merges into the base config instead of replacing its section.
"""

from __future__ import annotations

from fnmatch import fnmatchcase
from pathlib import Path

import pytest

from flows.dags import ARM, FACE, KEYFRAME, get_pipeline
from physanim.config import ConfigError, load_config
from physanim.dynamics import Figure
from physanim.dynamics.keyframes import KeyframeSpec, world_constraints
from physanim.pipeline import Pipeline
from physanim.pipeline.sweep import load_sweep, plan_sweep
from tasks.keyframes import project_path
from tests.commands import ROOT

CONFIGS = ROOT / "configs"

#: How each shipped file is used: a pipeline's default, an overlay (-c) on a pipeline's
#: default, a keyframe or figure file, or a sweep. Every file must match exactly one rule.
OVERLAYS: dict[str, Pipeline] = {
    "models/*.yaml": FACE,
    "materials/*.yaml": FACE,
    "drives/*.yaml": FACE,
    "gestures/*.yaml": FACE,
    "meshes/*.yaml": FACE,
    "keyframe_walk.yaml": KEYFRAME,
}
DEFAULTS = {p.default_config.relative_to(CONFIGS).as_posix(): p for p in (FACE, ARM, KEYFRAME)}


def shipped(pattern: str) -> list[Path]:
    return sorted(CONFIGS.glob(pattern))


def matches(path: Path, rule: str) -> bool:
    """``path`` (under configs/) matches ``rule``, a glob relative to configs/."""
    return fnmatchcase(path.relative_to(CONFIGS).as_posix(), rule)


def test_every_shipped_file_is_covered_by_a_rule() -> None:
    rules = [*OVERLAYS, *DEFAULTS, "keyframes/*.yaml", "figures/*.yaml", "sweeps/*.yaml"]
    for path in shipped("**/*.yaml"):
        matched = [r for r in rules if matches(path, r)]
        assert len(matched) == 1, f"{path}: add it to a rule of this test (matched {matched})"


@pytest.mark.parametrize("name", sorted(DEFAULTS))
def test_pipeline_defaults_validate(name: str) -> None:
    pipeline = DEFAULTS[name]
    load_config(pipeline.config_model(), [pipeline.default_config])


@pytest.mark.parametrize(
    "path", [p for pattern in OVERLAYS for p in shipped(pattern)], ids=lambda p: p.name
)
def test_overlays_validate_on_their_pipeline(path: Path) -> None:
    pipeline = next(p for rule, p in OVERLAYS.items() if matches(path, rule))
    cfg, origins = load_config(pipeline.config_model(), [pipeline.default_config, path])
    assert any(o == str(path) for o in origins.values())  # the file did set something
    if pipeline is FACE and "model" in path.parts[-2]:
        assert cfg.materials.model.name == path.stem  # type: ignore[attr-defined]


@pytest.mark.parametrize("path", shipped("keyframes/*.yaml"), ids=lambda p: p.name)
def test_keyframe_files_name_joints_of_their_figure(path: Path) -> None:
    spec = KeyframeSpec.from_yaml(path)
    figure = Figure.from_yaml(spec.figure)
    world_constraints(figure, spec)  # raises on a joint the figure lacks
    named = {n for k in spec.keys for n in (*k.angles, *k.velocities)}
    named |= {n for s in spec.simulate for n in (*s.subtrees, *s.joints)}
    named |= set(spec.friction) - {"default"}
    if spec.path is not None and spec.path.heading_joint:
        named.add(spec.path.heading_joint)
    assert named <= set(figure.joint_names), named - set(figure.joint_names)


def test_keyframe_configs_name_shipped_keyframe_files() -> None:
    for files in (
        [KEYFRAME.default_config],
        [KEYFRAME.default_config, CONFIGS / "keyframe_walk.yaml"],
    ):
        cfg, _ = load_config(KEYFRAME.config_model(), files)
        assert project_path(cfg.keyframes.file).is_file()  # type: ignore[attr-defined]


@pytest.mark.parametrize("path", shipped("figures/*.yaml"), ids=lambda p: p.name)
def test_figure_files_build(path: Path) -> None:
    assert Figure.from_yaml(path).n_dof > 0


@pytest.mark.parametrize("path", shipped("sweeps/*.yaml"), ids=lambda p: p.name)
def test_sweep_files_plan_every_variant(path: Path, tmp_path: Path, monkeypatch) -> None:
    """Each shipped sweep validates every variant's config and plans it (store in tmp_path;
    nothing runs), from the repository root as the README runs it."""
    monkeypatch.chdir(ROOT)
    sweep = tmp_path / path.name
    sweep.write_text(path.read_text() + f"\nset: {{dataset.store: {tmp_path / 'store.zarr'}}}\n")
    plan = plan_sweep(sweep, get_pipeline)
    keys = [tuple(k.items()) for k in plan.keys.values()]
    assert len(plan.variants) >= 2 and len(set(keys)) == len(plan.variants)
    assert {j.entry.stage for j in plan.jobs} >= {"materials", "simulate"}


def test_a_nested_value_merges_into_the_default_section() -> None:
    """``--set materials.model.default.E_kPa=96.2`` (the stiffness sweep's grid) changes E of
    the default uniform model and keeps its other values; over a materials file it changes
    that file's model."""
    model = FACE.config_model()
    base, _ = load_config(model, [FACE.default_config])
    cfg, origins = load_config(model, [FACE.default_config], ["materials.model.default.E_kPa=96.2"])
    expected = base.materials.model.default.model_copy(update={"E_kPa": 96.2})  # type: ignore[attr-defined]
    assert cfg.materials.model.default == expected  # type: ignore[attr-defined]
    assert cfg.materials.model.name == base.materials.model.name  # type: ignore[attr-defined]
    assert origins["materials.model.default.E_kPa"].startswith("--set")
    # the default's own value given explicitly is the same config (same content keys)
    same, _ = load_config(model, [FACE.default_config], ["materials.model.default.E_kPa=192.4"])
    assert same.model_dump() == base.model_dump()
    files = [FACE.default_config, CONFIGS / "models" / "model2.yaml"]
    model2, _ = load_config(model, files)
    edited, _ = load_config(model, files, ["materials.model.default.nu=0.45"])
    assert edited.materials.model.regions == model2.materials.model.regions  # type: ignore[attr-defined]
    assert edited.materials.model.default.nu == 0.45  # type: ignore[attr-defined]
    # a misspelt nested key is still an error naming the allowed keys
    with pytest.raises(ConfigError, match=r"E_kP: unknown key; allowed keys here: E_kPa"):
        load_config(model, [FACE.default_config], ["materials.model.default.E_kP=96.2"])


def test_stiffness_sweep_grid_varies_only_E(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(ROOT)
    _, variants = load_sweep(CONFIGS / "sweeps" / "stiffness.yaml")
    for v in variants:
        cfg, _ = load_config(FACE.config_model(), [FACE.default_config, *v.configs], v.overrides)
        default = cfg.materials.model.default  # type: ignore[attr-defined]
        assert (default.nu, default.eta_Pa_s, default.rho_kg_m3) == (0.495, 476.8, 1100.0)
    assert [v.name for v in variants] == [
        f"materials.model.default.E_kPa={e}" for e in (96.2, 192.4, 384.8)
    ]


def test_scan_settings_under_align_name_their_new_section(tmp_path: Path) -> None:
    """The scan settings moved from ``align`` to the ``scan`` stage: an old config is refused
    with the key, the file and the new place, and the same value under ``scan`` loads."""
    old = tmp_path / "old.yaml"
    old.write_text("align: {remesh_edge_length_m: 0.001, lip_band_m: 0.012}\n")
    with pytest.raises(ConfigError, match=r"old.yaml.*remesh_edge_length_m moved to the scan"):
        load_config(FACE.config_model(), [FACE.default_config, old], [])
    new = tmp_path / "new.yaml"
    new.write_text("align: {lip_band_m: 0.012}\nscan: {remesh_edge_length_m: 0.001}\n")
    cfg, _ = load_config(FACE.config_model(), [FACE.default_config, new], [])
    assert cfg.scan.remesh_edge_length_m == 0.001 and cfg.align.lip_band_m == 0.012

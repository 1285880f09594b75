"""Config fuzzing (issue #35): Hypothesis strategies over the face pipeline's pydantic config
model, given as ``--set`` values, as ``-c`` files and in sweep files.

Every generated input is either refused with a ``ConfigError`` whose message names the source
(the file, or the ``--set`` text) and the dotted key, or accepted with exactly the value given
at that key and every other value the default's: never another exception (a traceback for the
user), never a silently different config. ``PHYSANIM_FUZZ_EXAMPLES=N`` runs N examples per
test (the long form: ``python -m tests.capture.fuzz_long``); ``STATS`` counts the outcomes.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import types
from collections import Counter
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin

import annotated_types as at
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flows.dags import FACE, get_pipeline
from physanim.config import ConfigError, load_config
from physanim.config.loader import _model_of, _yaml
from physanim.pipeline.sweep import plan_sweep

MODEL = FACE.config_model()
DEFAULT = FACE.default_config
BASE = load_config(MODEL, [DEFAULT])[0]
#: examples per test (the long form sets PHYSANIM_FUZZ_EXAMPLES)
EXAMPLES = int(os.environ.get("PHYSANIM_FUZZ_EXAMPLES", "0"))
#: outcome counts, by (test, outcome)
STATS: Counter[tuple[str, str]] = Counter()
FUZZ = settings(
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def leaves(model: Any = MODEL, prefix: str = "") -> dict[str, Any]:
    """Dotted key -> pydantic FieldInfo of every leaf of ``model`` (nested models walked)."""
    out = {}
    for name, info in model.model_fields.items():
        sub = _model_of(info.annotation)
        if sub is not None:
            out.update(leaves(sub, f"{prefix}{name}."))
        else:
            out[prefix + name] = info
    return out


LEAVES = leaves()
SECTIONS = sorted(MODEL.model_fields)


def _bounds(info: Any) -> dict[str, float]:
    out = {}
    for m in info.metadata:
        for kind in ("gt", "ge", "lt", "le"):
            if isinstance(m, getattr(at, kind.title())):
                out[kind] = getattr(m, kind)
    return out


def _core(annotation: Any) -> tuple[Any, bool]:
    """(the annotation without ``| None``, whether None is allowed)."""
    if get_origin(annotation) in (Union, types.UnionType):
        args = [a for a in get_args(annotation) if a is not type(None)]
        return (args[0] if len(args) == 1 else annotation), True
    return annotation, False


def valid_values(info: Any) -> st.SearchStrategy[Any]:
    """Values the field's annotation and bounds allow."""
    ann, optional = _core(info.annotation)
    b = _bounds(info)
    if get_origin(ann) is Literal:
        s = st.sampled_from(get_args(ann))
    elif ann is bool:
        s = st.booleans()
    elif ann is int:
        lo = b.get("ge", b["gt"] + 1 if "gt" in b else -(10**6))
        hi = b.get("le", b["lt"] - 1 if "lt" in b else 10**6)
        s = st.integers(int(lo), int(hi))
    elif ann is float:
        s = st.floats(
            b.get("ge", b.get("gt", -1e6)),
            b.get("le", b.get("lt", 1e6)),
            exclude_min="gt" in b,
            exclude_max="lt" in b,
            allow_nan=False,
            allow_infinity=False,
        )
    elif ann is str:
        pattern = [m.pattern for m in info.metadata if getattr(m, "pattern", None)]
        s = st.from_regex(pattern[0], fullmatch=True) if pattern else st.text(min_size=1)
    elif get_origin(ann) is tuple:
        s = st.tuples(*(st.floats(-10, 10, allow_nan=False) for _ in get_args(ann)))
    elif get_origin(ann) is list:
        s = st.lists(st.text(min_size=1), max_size=3)
    else:  # a mapping (regions, stiffness overrides): not generated as valid
        s = st.nothing()
    return st.one_of(s, st.none()) if optional else s


def invalid_values(info: Any) -> st.SearchStrategy[Any]:
    """Values of the wrong type, out of range, not finite, or a section in place of a value."""
    ann, optional = _core(info.annotation)
    b = _bounds(info)
    bad: list[Any] = [[1, 2], {"x": 1}, "abc"]
    if ann in (int, float):
        bad += [float("nan"), float("inf"), -float("inf"), True]
        bad += [b[k] for k in ("gt", "lt") if k in b]
        bad += [b["ge"] - 1, b["ge"] - 1e-3] if "ge" in b else []
        bad += [b["le"] + 1, b["le"] * 10 + 1] if "le" in b else []
        bad += [1.5] if ann is int else []
    if get_origin(ann) is Literal:
        bad += ["not-a-choice", 3]
    if get_origin(ann) is tuple:
        bad += [[1.0], [1.0, 2.0, 3.0, 4.0], [1.0, "x", 2.0]]
    if not optional:
        bad.append(None)
    return st.sampled_from(bad)


@st.composite
def overrides(draw: st.DrawFn) -> tuple[str, Any, bool | None]:
    """(dotted key, value, valid: True/False, None when not known)."""
    choice = draw(st.integers(0, 9))
    if choice == 0:  # an unknown key in a section, or an unknown section
        section = draw(st.sampled_from([*SECTIONS, "nosuchsection"]))
        name = draw(st.from_regex(r"[a-z][a-z_]{0,10}", fullmatch=True))
        key = f"{section}.{name}"
        if key in LEAVES or section in ("materials",) or name in MODEL.model_fields:
            return key, 1.0, None
        value = draw(st.one_of(st.integers(), st.text(max_size=5), st.booleans()))
        return key, value, key.split(".")[0] == "materials"
    key = draw(st.sampled_from(sorted(LEAVES)))
    if choice <= 4:
        return key, draw(valid_values(LEAVES[key])), True
    return key, draw(invalid_values(LEAVES[key])), False


def yaml_text(value: Any) -> str:
    """``value`` as YAML flow text, as a user types it after ``--set key=``."""
    if isinstance(value, float) and not math.isfinite(value):
        return ".nan" if math.isnan(value) else (".inf" if value > 0 else "-.inf")
    value = list(value) if isinstance(value, tuple) else value
    text = yaml.safe_dump(value, default_flow_style=True, width=10**9)  # escapes non-ASCII
    return text.removesuffix("\n").removesuffix("\n...").strip()


def get(tree: Any, dotted: str) -> Any:
    """The value at ``dotted`` of a config (models, mappings); ``...`` when there is none."""
    for part in dotted.split("."):
        if isinstance(tree, dict):
            tree = tree.get(part, ...)
        else:
            tree = getattr(tree, part, ...)
        if tree is ... or tree is None:
            return tree
    return tree


def same(given: Any, got: Any) -> bool:
    """Whether the validated ``got`` is the value ``given`` (pydantic's lax conversions)."""
    if isinstance(given, list | tuple) and isinstance(got, list | tuple):
        return len(given) == len(got) and all(map(same, given, got))
    if isinstance(given, str) and isinstance(got, bool):  # pydantic's words for booleans
        words = {"0": False, "off": False, "f": False, "false": False, "n": False,
                 "no": False, "1": True, "on": True, "t": True, "true": True, "y": True,
                 "yes": True}  # fmt: skip
        return words.get(given.strip().lower()) is got
    if isinstance(given, str) and isinstance(got, int | float) and not isinstance(got, bool):
        try:
            return float(given) == got
        except ValueError:
            return False
    return given == got and (given is None) == (got is None)


def _names(message: str, source: str, key: str) -> bool:
    """Some line of a ConfigError names ``source`` and the key, or the part of it that is
    wrong (``nosuchsection`` of ``nosuchsection.x``; ``simulate.reduced.basis_model.name``
    of ``simulate.reduced.basis_model.default.E_kPa``: a section given in part)."""
    if source.startswith("--set "):  # the --set text as given, or quoted (repr)
        sources = (source, f"--set {source.removeprefix('--set ')!r}")
    else:
        sources = (source,)
    parts = key.split(".")
    stems = [".".join(parts[:n]) for n in range(len(parts), 0, -1)]
    return any(
        s in line and any(f"{stem}:" in line or f"{stem}." in line for stem in stems)
        for s in sources
        for line in message.split("\n")  # not splitlines: the text may hold U+0085
    )


def judge(files: list[str], sets: list[str], source: str, key: str, value: Any) -> str:
    """Load the config; the outcome (accepted/refused) or raise AssertionError on a defect."""
    try:
        cfg = load_config(MODEL, [DEFAULT, *files], sets)[0]
    except ConfigError as exc:
        assert _names(str(exc), source, key), f"refusal does not name {source} / {key}: {exc}"
        return "refused"
    got = get(cfg, key)
    assert same(value, got), f"{key}: gave {value!r}, the config has {got!r}"
    for other in LEAVES:  # nothing else changed
        if not (other.startswith(key) or key.startswith(other.rsplit(".", 1)[0] + ".")):
            assert get(cfg, other) == get(BASE, other), f"{key}={value!r} changed {other}"
    return "accepted"


@settings(FUZZ, max_examples=EXAMPLES or 1000)
@given(case=overrides())
def test_set_overrides(case: tuple[str, Any, bool | None]) -> None:
    """``--set key=value``: accepted exactly, or refused naming the --set and the key."""
    key, value, _ = case
    text = f"{key}={yaml_text(value)}"
    outcome = judge([], [text], f"--set {text}", key, value)
    STATS[("--set value", outcome)] += 1


@settings(FUZZ, max_examples=EXAMPLES or 400)
@given(case=overrides())
def test_config_files(case: tuple[str, Any, bool | None]) -> None:
    """The same values in a ``-c`` file: accepted exactly, or refused naming file and key."""
    key, value, _ = case
    tree: Any = value
    for part in reversed(key.split(".")):
        tree = {part: tree}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.yaml"
        path.write_text(yaml.safe_dump(tree))
        outcome = judge([str(path)], [], str(path), key, value)
    STATS[("-c file value", outcome)] += 1


CHARS = st.characters(codec="utf-8", exclude_categories=["Cs"])


@settings(FUZZ, max_examples=EXAMPLES or 500)
@given(
    text=st.one_of(
        st.text(CHARS, max_size=40),  # anything
        st.builds(  # a known key and any text as its value, as a user may type it
            "{}={}".format, st.sampled_from(sorted(LEAVES)), st.text(CHARS, max_size=20)
        ),
    )
)
def test_raw_set_text(text: str) -> None:
    """Any text after ``--set``: refused naming it, or accepted with the value its YAML
    gives (never another exception)."""
    try:
        cfg = load_config(MODEL, [DEFAULT], [text])[0]
    except ConfigError as exc:
        assert f"--set {text}" in str(exc) or f"--set {text!r}" in str(exc), str(exc)
        STATS[("raw --set text", "refused")] += 1
        return
    key, raw = text.split("=", 1)
    value = _yaml(raw) if raw.strip() else ""
    assert same(value, get(cfg, key.strip())), f"{text}: the config has {get(cfg, key)!r}"
    STATS[("raw --set text", "accepted")] += 1


@st.composite
def sweep_files(draw: st.DrawFn) -> dict[str, Any]:
    """A sweep file's content: valid parts mixed with damaged ones."""
    spec: dict[str, Any] = {}
    if draw(st.booleans()):
        spec["pipeline"] = draw(st.sampled_from(["face", "face", "nosuchdag", 3, ["face"]]))
    if draw(st.booleans()):
        spec["datasets"] = draw(st.sampled_from([["demo"], [], "demo", ["a", "b"], [None]]))
    pairs = st.lists(overrides(), max_size=2)
    if draw(st.booleans()):
        spec["set"] = {k: v for k, v, _ in draw(pairs)}
    if draw(st.booleans()):
        spec["grid"] = {k: draw(st.lists(st.just(v), min_size=1, max_size=2)) for k, v, _ in
                        draw(pairs)}  # fmt: skip
    if draw(st.booleans()):
        names = st.sampled_from(["a", "b", "a", ""])
        spec["variants"] = [
            {"name": draw(names), "set": {k: v for k, v, _ in draw(pairs)}}
            for _ in range(draw(st.integers(0, 3)))
        ]
    if draw(st.integers(0, 9)) == 0:
        spec[draw(st.sampled_from(["unknown", "configs"]))] = draw(
            st.sampled_from([["configs/nosuch.yaml"], 5, "x"])
        )
    return spec


@settings(FUZZ, max_examples=EXAMPLES // 4 or 120)
@given(spec=sweep_files())
def test_sweep_files(spec: dict[str, Any]) -> None:
    """A sweep file is planned (every variant has the sweep's values) or refused naming the
    sweep file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sweep.yaml"
        datasets = spec.get("datasets")
        if isinstance(datasets, list):  # datasets in the temporary folder: stores go there
            spec = {**spec, "datasets": [str(Path(tmp) / str(d)) for d in datasets]}
        path.write_text(yaml.safe_dump(spec))
        try:
            # in the temporary folder: a store path the sweep sets (dataset.store=abc) is
            # created relative to the working directory
            with contextlib.chdir(tmp):
                plan = plan_sweep(path, get_pipeline)
        except (ConfigError, ValueError) as exc:  # what `physanim sweep` reports in one line
            # the sweep file named on the first line (a variant's problems follow, one a line)
            # or on each problem's line
            lines = [x for x in str(exc).split("\n") if x.strip() != "invalid config:"]
            named = str(path) in lines[0] or all(str(path) in x for x in lines)
            assert named or "nosuchdag" in str(exc), str(exc)
            STATS[("sweep file", "refused")] += 1
            return
    for v in plan.variants:
        cfg = plan.configs[v.name]
        for key, value in spec.get("set", {}).items():
            given_by_variant = any(
                key in x.get("set", {}) for x in spec.get("variants", []) if x["name"] == v.name
            )
            if key not in spec.get("grid", {}) and not given_by_variant:
                assert same(value, get(cfg, key)), f"{v.name}: {key} {get(cfg, key)!r}"
    STATS[("sweep file", "accepted")] += 1


def test_sweep_keeps_characters_beyond_the_bmp(tmp_path: Path) -> None:
    """A sweep value beyond U+FFFF reaches the config intact (it came back as two broken
    characters when the values were passed on as ASCII-escaped JSON)."""
    path = tmp_path / "sweep.yaml"
    spec = {"datasets": [str(tmp_path / "ds")], "set": {"materials.model.description": "😀"}}
    path.write_text(yaml.safe_dump(spec))
    plan = plan_sweep(path, get_pipeline)
    (cfg,) = plan.configs.values()
    assert cfg.materials.model.description == "😀"

"""Load YAML config files, merge them with overrides and validate them with pydantic.

Merge order (later wins, key by key): the base file (``configs/default.yaml``), then each
``-c FILE`` in the order given, then each ``--set dotted.key=value``.  Every leaf remembers the
file (or ``--set``) it came from, so a validation error names the file, the dotted key and the
allowed range.
"""

from __future__ import annotations

import copy
import math
import re
import types
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar, Union, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError

M = TypeVar("M", bound=BaseModel)


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads ``1e-3`` as a float (PyYAML's YAML 1.1 wants ``1.0e-3``)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+][0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def _yaml(text: str):
    return yaml.load(text, Loader=_Loader)  # noqa: S506 - a SafeLoader subclass


def _yaml_error(exc: yaml.YAMLError) -> str:
    """A YAML error on one line: the problem and where (line, column), else its text."""
    problem = getattr(exc, "problem", None)
    mark = getattr(exc, "problem_mark", None)
    if problem is None:
        return " ".join(str(exc).split())
    at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{at}"


class ConfigError(ValueError):
    """A config file or override is missing, malformed or invalid; the message says where."""


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read one YAML mapping; clear errors for a missing file, bad YAML or a non-mapping."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: config file not found (check the path given to -c/--config)")
    try:
        data = _yaml(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {_yaml_error(exc)}") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{path}: top level must be a mapping of sections, got {type(data).__name__}"
        )
    return data


def _merge(
    base: dict[str, Any], over: Mapping[str, Any], source: str, origins: dict[str, str], prefix=""
) -> None:
    for k, v in over.items():
        dotted = f"{prefix}{k}"
        if isinstance(v, Mapping) and isinstance(base.get(k), dict):
            _merge(base[k], v, source, origins, dotted + ".")
            # a section answers to the last source that set anything in it: a check across
            # its fields (a section-level error) names the file or --set that changed it
            origins[dotted] = source
        else:
            base[k] = copy.deepcopy(v)
            for o in [o for o in origins if o.startswith(dotted + ".")]:
                del origins[o]
            origins[dotted] = source
            if isinstance(v, Mapping):
                _record(v, source, origins, dotted + ".")


def _record(tree: Mapping[str, Any], source: str, origins: dict[str, str], prefix: str) -> None:
    for k, v in tree.items():
        origins[f"{prefix}{k}"] = source
        if isinstance(v, Mapping):
            _record(v, source, origins, f"{prefix}{k}.")


def deep_merged(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``base`` with ``over`` merged in key by key (nested mappings merge too)."""
    out = copy.deepcopy(dict(base))
    _merge(out, over, "", {})
    return out


def parse_override(text: str) -> dict[str, Any]:
    """Turn ``"simulate.dt=0.001"`` into ``{"simulate": {"dt": 0.001}}`` (value parsed as YAML)."""
    if "=" not in text:
        raise ConfigError(f"--set {text!r}: expected dotted.key=value, e.g. simulate.dt=0.001")
    key, raw = text.split("=", 1)
    parts = key.strip().split(".")
    if not all(p.isidentifier() for p in parts):
        raise ConfigError(f"--set {text!r}: {key!r} is not a dotted key like simulate.dt")
    try:
        value = _yaml(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ConfigError(f"--set {text!r}: value is not valid YAML: {_yaml_error(exc)}") from exc
    tree: dict[str, Any] = {parts[-1]: value}
    for p in reversed(parts[:-1]):
        tree = {p: tree}
    return tree


def _merge_file(
    tree: dict[str, Any], path: Path, origins: dict[str, str], seen: tuple[Path, ...]
) -> None:
    """Merge one file, after the files its ``include:`` list names (relative to it)."""
    data = load_yaml(path)
    includes = data.pop("include", [])
    if isinstance(includes, str):
        includes = [includes]
    if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
        raise ConfigError(f"{path}: include must be a file name or a list of file names")
    for inc in includes:
        target = (path.parent / inc).resolve()
        if target in seen:
            raise ConfigError(f"{path}: include cycle through {target}")
        _merge_file(tree, target, origins, (*seen, target))
    _merge(tree, data, str(path), origins)


def merge_sources(
    files: Iterable[str | Path], overrides: Iterable[str] = ()
) -> tuple[dict[str, Any], dict[str, str]]:
    """Merge files then overrides; returns (raw tree, origin of each dotted key).

    A file may start with ``include: [other.yaml, ...]`` (paths relative to it); the included
    files are merged first, then the file itself.
    """
    tree: dict[str, Any] = {}
    origins: dict[str, str] = {}
    for f in files:
        _merge_file(tree, Path(f), origins, (Path(f).resolve(),))
    for o in overrides:
        _merge(tree, parse_override(o), f"--set {o}", origins)
    return tree, origins


def _origin(dotted: str, origins: Mapping[str, str]) -> str:
    parts = dotted.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in origins:
            return origins[".".join(parts[:n])]
    return "(defaults)"


def _model_of(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model a field holds: ``X``, ``X | None`` or ``Optional[X]`` (else None)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if get_origin(annotation) in (Union, types.UnionType):
        models = [a for a in get_args(annotation) if _model_of(a) is not None]
        return models[0] if len(models) == 1 else None
    return None


def with_defaults(
    model: type[BaseModel], tree: Mapping[str, Any], default: BaseModel | None = None
) -> dict[str, Any]:
    """``tree`` with every nested section it gives completed from the section's default.

    A key that a file or ``--set`` gives inside a section whose default is a whole model
    (``--set materials.model.default.E_kPa=96.2``, where ``materials.model`` defaults to the
    uniform model) changes that one value: the section's other values stay the default's,
    as they would if the default were written in the base file.  Values that are not models
    (numbers, lists, mappings of names) replace the default's as a whole.  ``default``: the
    instance whose values complete ``tree`` (None: the model's own field defaults).
    """
    out: dict[str, Any] = {}
    for name, field in model.model_fields.items():
        key = field.alias or name
        if key in tree:
            value, sub = tree[key], _model_of(field.annotation)
            if sub is not None and isinstance(value, Mapping):
                base = getattr(default, name) if default is not None else None
                if base is None and not field.is_required():
                    base = field.get_default(call_default_factory=True)
                value = with_defaults(sub, value, base if isinstance(base, BaseModel) else None)
            out[key] = value
        elif default is not None:
            given = getattr(default, name)
            if field.is_required() or given != field.get_default(call_default_factory=True):
                out[key] = default.model_dump(by_alias=True, include={name})[key]
    out.update({k: v for k, v in tree.items() if k not in out})  # unknown keys: reported
    return out


def _allowed(model: type[BaseModel], loc: tuple[Any, ...]) -> list[str]:
    """Field names accepted at the parent of ``loc`` (for unknown-key messages)."""
    current: Any = model
    for part in loc[:-1]:
        fields = getattr(current, "model_fields", None)
        if not fields or part not in fields:
            return []
        current = _model_of(fields[part].annotation)
    fields = getattr(current, "model_fields", None)
    return sorted(fields) if fields else []


def _describe(err: Mapping[str, Any], model: type[BaseModel]) -> str:
    kind, ctx, got = err["type"], err.get("ctx", {}), err.get("input")
    bounds = {
        "greater_than": ">",
        "greater_than_equal": ">=",
        "less_than": "<",
        "less_than_equal": "<=",
    }
    if kind == "extra_forbidden":
        allowed = _allowed(model, tuple(err["loc"]))
        return "unknown key" + (f"; allowed keys here: {', '.join(allowed)}" if allowed else "")
    if kind in bounds:
        (limit,) = ctx.values()
        return f"must be {bounds[kind]} {limit} (got {got!r})"
    if kind == "missing":
        return "required key is missing"
    return f"{err['msg']} (got {got!r})"


def _non_finite(tree: Any, prefix: str = "") -> Iterator[tuple[str, float]]:
    """(dotted key, value) of every NaN or infinite number in a nested dict/list."""
    if isinstance(tree, float) and not math.isfinite(tree):
        yield prefix, tree
    elif isinstance(tree, Mapping):
        for k, v in tree.items():
            yield from _non_finite(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(tree, list | tuple):
        for i, v in enumerate(tree):
            yield from _non_finite(v, f"{prefix}[{i}]")


def validate(model: type[M], tree: Mapping[str, Any], origins: Mapping[str, str]) -> M:
    """Validate a merged tree; raise ConfigError listing every problem with file and dotted key.

    A nested section that ``tree`` gives only in part is completed from its default first
    (``with_defaults``).  NaN and infinities are refused too: parameters enter content keys,
    which need finite numbers.
    """
    try:
        result = model.model_validate(with_defaults(model, tree))
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            dotted = ".".join(str(p) for p in err["loc"])
            lines.append(f"{_origin(dotted, origins)}: {dotted}: {_describe(err, model)}")
        raise ConfigError("invalid config:\n  " + "\n  ".join(lines)) from None
    bad = [
        f"{_origin(dotted.split('[')[0], origins)}: {dotted}: must be a finite number "
        f"(got {value!r})"
        for dotted, value in _non_finite(result.model_dump())
    ]
    if bad:
        raise ConfigError("invalid config:\n  " + "\n  ".join(bad))
    return result


def load_config(
    model: type[M], files: Iterable[str | Path], overrides: Iterable[str] = ()
) -> tuple[M, dict[str, str]]:
    """Merge ``files`` and ``overrides`` (in that order) and validate against ``model``."""
    tree, origins = merge_sources(files, overrides)
    return validate(model, tree, origins), origins

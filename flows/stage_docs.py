"""docs/STAGES.md, generated from the stage declarations: ``python -m flows.stage_docs``.

For each DAG of ``flows.dags`` (face, keyframe, arm) and each of its stages in order: name,
code version, doc, upstream stages, the fields of its params model (name, type, allowed range,
default, description; nested models flattened as dotted names, as ``--set`` writes them) and
the fields and docstring of its output dataclass. The text depends only on the declarations,
so it is the same on every machine; ``--check`` exits with 1 when the committed file differs
(``make docs`` regenerates it).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import sys
import types
import typing
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import annotated_types
from pydantic import BaseModel
from pydantic.fields import FieldInfo
from pydantic_core import PydanticUndefined, to_jsonable_python

from physanim.pipeline import Pipeline, StageSpec

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "STAGES.md"
#: the DAGs documented, in this order
DAGS = ("face", "keyframe", "arm")
#: defaults longer than this are summarised (their items are listed as rows of their own)
_MAX_DEFAULT = 60
_COMMAND = "python -m flows.stage_docs"


def _cell(text: str) -> str:
    """``text`` as one Markdown table cell: one line, pipes escaped."""
    return " ".join(text.split()).replace("|", "\\|")


def _doc(obj: Any) -> str:
    """The docstring written for ``obj`` (not the one ``dataclass`` makes up), cleaned."""
    doc = inspect.getdoc(obj) or ""
    if dataclasses.is_dataclass(obj) and doc.startswith(f"{obj.__name__}("):
        return ""
    return doc


def type_name(annotation: Any) -> str:
    """A type annotation as a reader writes it: ``float``, ``'a' | 'b'``, ``list[str] | None``."""
    if annotation is None or annotation is type(None):
        return "None"
    if annotation is Any:
        return "Any"
    if isinstance(annotation, str):
        return annotation
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is typing.Literal:
        return " | ".join(json.dumps(a).replace('"', "'") for a in args)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(type_name(a) for a in args)
    if origin is typing.Annotated:
        return type_name(args[0])
    if origin is not None:
        name = getattr(origin, "__name__", str(origin))
        return f"{name}[{', '.join('...' if a is Ellipsis else type_name(a) for a in args)}]"
    return getattr(annotation, "__name__", str(annotation).replace("typing.", ""))


def _constraints(field: FieldInfo) -> str:
    """The field's allowed range from its ``Field(ge=..., ...)`` constraints, e.g. ``> 0, <= 1``."""
    out = []
    for m in field.metadata:
        for attr, sign in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
            if isinstance(m, getattr(annotated_types, attr.title())):
                out.append(f"{sign} {json.dumps(to_jsonable_python(getattr(m, attr)))}")
        if isinstance(m, annotated_types.MinLen):
            out.append(f"length >= {m.min_length}")
        if isinstance(m, annotated_types.MaxLen):
            out.append(f"length <= {m.max_length}")
    return ", ".join(out)


def _default(value: Any) -> str:
    """A default as JSON (``null``, ``0.001``, ``"auto"``), summarised when long."""
    if value is PydanticUndefined:
        return "required"
    data = to_jsonable_python(value)
    text = json.dumps(data, ensure_ascii=False)
    if len(text) <= _MAX_DEFAULT:
        return f"`{text}`"
    if isinstance(data, list):
        return f"{len(data)} items"
    if isinstance(data, dict):
        return f"{len(data)} entries"
    return f"`{text[: _MAX_DEFAULT - 3]}...`"


def _model_in(annotation: Any) -> tuple[str, type[BaseModel]] | None:
    """A params model nested in ``annotation``, with the path suffix of its fields: ``""``
    for ``M`` or ``M | None``, ``".<key>"`` for ``dict[str, M]``, ``"[i]"`` for ``list[M]``."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return "", annotation
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType):
        found = [m for m in (_model_in(a) for a in args if a is not type(None)) if m]
        return found[0] if len(found) == 1 and len(args) <= 2 else None
    if origin is dict and len(args) == 2:
        inner = _model_in(args[1])
        return (".<key>" + inner[0], inner[1]) if inner else None
    if origin in (list, tuple) and len(args) == 1:
        inner = _model_in(args[0])
        return ("[i]" + inner[0], inner[1]) if inner else None
    return None


def params_rows(model: type[BaseModel], value: Any = None, prefix: str = "") -> Iterator[tuple]:
    """(dotted name, type, allowed, default, description) of every field of ``model``, nested
    models flattened; defaults read from ``value`` (an instance) where given, else the field's."""
    for name, field in model.model_fields.items():
        if isinstance(value, BaseModel):
            default = getattr(value, name)
        else:
            default = field.get_default(call_default_factory=True)
        nested = _model_in(field.annotation)
        shown = "fields below" if nested and isinstance(default, BaseModel) else _default(default)
        desc = field.description or (_doc(nested[1]).split("\n\n")[0] if nested else "")
        yield (
            prefix + name,
            type_name(field.annotation),
            _constraints(field),
            shown,
            desc,
        )
        if nested:
            suffix, inner = nested
            sub = default if suffix == "" and isinstance(default, BaseModel) else None
            # the default's own class: a subclass (a registered material law) adds fields
            yield from params_rows(type(sub) if sub else inner, sub, f"{prefix}{name}{suffix}.")


def output_rows(cls: type, prefix: str = "", depth: int = 0) -> Iterator[tuple[str, str]]:
    """(dotted name, type as annotated) of every field of the output dataclass ``cls``; the
    fields of nested dataclasses follow their parent's row."""
    try:
        hints = typing.get_type_hints(cls)
    except Exception:  # an annotation only importable for type checkers: keep the text
        hints = {}
    for f in dataclasses.fields(cls):
        yield prefix + f.name, type_name(f.type)
        inner = hints.get(f.name)
        options = [a for a in typing.get_args(inner) if a is not type(None)] or [inner]
        nested = options[0] if len(options) == 1 else None
        if depth < 2 and isinstance(nested, type) and dataclasses.is_dataclass(nested):
            yield from output_rows(nested, f"{prefix}{f.name}.", depth + 1)


def _relative(path: Path) -> str:
    try:
        return path.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return path.name


def stage_text(stage: StageSpec, params: BaseModel | None = None) -> str:
    """One stage's section of STAGES.md; defaults read from ``params`` (the stage's params in
    the pipeline's default config), else from its params model."""
    section = stage.section or stage.name
    lines = [f"### {stage.name}", ""]
    facts = [f"version {stage.version}"]
    upstream = ", ".join(f"[{u}](#{u})" for u in stage.upstream)
    facts.append(f"upstream: {upstream or 'none'}")
    if stage.section:
        facts.append(f"settings from the `{stage.section}` section")
    if stage.varies:
        facts.append("varies (its output may differ between runs with the same key)")
    lines += ["; ".join(facts) + ".", ""]
    if stage.doc:
        lines += [stage.doc[0].upper() + stage.doc[1:] + ".", ""]
    if stage.files:
        files = ", ".join(f"`{p}` ({c})" for p, c in sorted(stage.files.items()))
        lines += [f"Files shown in the report: {files}.", ""]
    rows = list(params_rows(stage.params, params if params is not None else stage.params()))
    lines.append(f"**Parameters** (`{stage.params.__name__}`; `--set {section}.<name>=<value>`)")
    lines.append("")
    if rows:
        lines += ["| name | type | allowed | default | description |", "|---|---|---|---|---|"]
        for name, typ, allowed, default, desc in rows:
            cells = [f"`{name}`", f"`{typ}`", allowed, default, desc]
            lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    else:
        lines.append("None.")
    lines.append("")
    if stage.output is None:
        lines += ["**Output**: the stage writes its group itself (no declared dataclass).", ""]
        return "\n".join(lines)
    lines += [f"**Output** (`{stage.output.__name__}`)", ""]
    doc = _doc(stage.output)
    if doc:
        lines += [" ".join(p.split()) + "\n" for p in doc.split("\n\n")]
    fields = list(output_rows(stage.output))
    if fields:
        lines += ["| field | type |", "|---|---|"]
        lines += [f"| `{_cell(n)}` | `{_cell(t)}` |" for n, t in fields]
    else:
        lines.append("No fields: the output is its files.")
    lines.append("")
    return "\n".join(lines)


def pipeline_text(pipeline: Pipeline) -> str:
    """One DAG's section of STAGES.md: its stages in order, with the defaults of its default
    config file (the params model's own where the file is silent)."""
    from physanim.config.loader import load_config

    config, _ = load_config(pipeline.config_model(), [pipeline.default_config])
    lines = [
        f"## {pipeline.name} DAG",
        "",
        f"`physanim run -p {pipeline.name}`; default config "
        f"`{_relative(pipeline.default_config)}`. Stages in order: "
        + ", ".join(f"[{s.name}](#{s.name})" for s in pipeline.stages)
        + ".",
        "",
    ]
    stages = (stage_text(s, s.params_from(config)) for s in pipeline.stages)
    return "\n".join(lines) + "\n" + "\n".join(stages)


def document(pipelines: Sequence[Pipeline]) -> str:
    """The whole of STAGES.md for ``pipelines``."""
    head = [
        "# Stages",
        "",
        f"Generated by `{_COMMAND}` from the stage declarations (`flows/dags.py`,",
        "`tasks/*.py`): do not edit it by hand; `make docs` regenerates it and",
        f"`{_COMMAND} --check` fails when it is out of date. Each stage's parameters are",
        "its section of the config (`configs/default.yaml` for the face DAG), set with",
        "`-c FILE` or `--set section.name=value`; nested fields are written with dots. A",
        "default is the value in the DAG's default config file (the params model's own where",
        "the file does not set it). Why each stage's version changed:",
        "[CHANGELOG.md](../CHANGELOG.md).",
        "",
    ]
    for p in pipelines:
        head.append(f"- [{p.name} DAG](#{p.name}-dag): " + ", ".join(s.name for s in p.stages))
    text = "\n".join(head) + "\n\n" + "\n".join(pipeline_text(p) for p in pipelines)
    return text.rstrip("\n") + "\n"


def generate() -> str:
    """STAGES.md for the project's DAGs."""
    from flows.dags import get_pipeline

    return document([get_pipeline(name) for name in DAGS])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=_COMMAND, description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 when the file is stale")
    parser.add_argument("-o", "--output", type=Path, default=OUT, help="file to write or check")
    args = parser.parse_args(argv)
    text = generate()
    if args.check:
        if not args.output.exists() or args.output.read_text(encoding="utf-8") != text:
            print(f"{_relative(args.output)} is out of date: run {_COMMAND}", file=sys.stderr)
            return 1
        print(f"{_relative(args.output)} is up to date")
        return 0
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text, encoding="utf-8")
    print(f"wrote {_relative(args.output)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

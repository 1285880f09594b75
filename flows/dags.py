"""The DAGs, declared once: they drive the CLI (run, status, dag), the Prefect flows and reports.

Each stage lives in ``tasks/<stage>.py`` (its StageSpec: name, upstream, params model, code
version, compute function).  Stages that are not implemented yet are simply absent.  This module
does not import Prefect (planning and ``status`` never need it); ``flows.executors``'
``PrefectExecutor`` runs any of these DAGs as a Prefect flow named ``physanim-<dag>``, one task
per stage (``DaskExecutor``: on a Dask cluster).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

from physanim.capture.params import DemoParams
from physanim.pipeline import Pipeline, PipelineConfig, PlanEntry
from physanim.store import StageStore
from physanim.store.stage_store import LATEST
from tasks import (
    actuation,
    align,
    dense,
    evaluate,
    export,
    fit,
    ingest,
    materials,
    render,
    scan,
    simulate,
    tetra,
    tiles,
    track,
)

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def face_report(store: StageStore, entries: list[PlanEntry], config: PipelineConfig) -> Path | None:
    """The face run's HTML report in ``<run dir>/report/`` (variants side by side).

    Rebuilt when a stage ran or the latest run changed since it was written, so a warm run
    that changes nothing costs nothing here.
    """
    dataset = config.dataset
    out = dataset.run_dir / "report"
    index, pointer = out / "index.html", store.root / LATEST
    fresh = index.exists() and (
        not pointer.exists() or pointer.stat().st_mtime <= index.stat().st_mtime
    )
    if fresh and not any(e.action == "run" for e in entries):
        return index
    from physanim.render.run_report import write_run_report  # matplotlib: only when written

    return write_run_report(FACE, store, entries, out, f"physanim: {dataset.name}")


FACE = Pipeline(
    name="face",
    stages=(
        ingest.SPEC,
        track.SPEC,
        fit.SPEC,
        scan.SPEC,
        align.SPEC,
        dense.SPEC,
        tiles.SPEC,
        tetra.SPEC,
        materials.SPEC,
        actuation.SPEC,
        simulate.SPEC,
        evaluate.SPEC,
        render.SPEC,
        export.SPEC,
    ),
    default_config=CONFIGS / "default.yaml",
    extra_sections={"demo": DemoParams},
    prepare=ingest.ensure_demo,
    report=face_report,
)


def _arm() -> Pipeline:
    from tasks import arm_render, muscles

    return Pipeline(
        name="arm",
        stages=(muscles.SPEC, arm_render.SPEC),
        default_config=CONFIGS / "arm" / "default.yaml",
    )


def _keyframe() -> Pipeline:
    from tasks import keyframe_render, keyframes

    return Pipeline(
        name="keyframe",
        stages=(keyframes.SPEC, keyframe_render.SPEC),
        default_config=CONFIGS / "keyframe.yaml",
    )


# the arm and keyframe DAGs import the rigid-body and muscle code (numba): built on first use,
# so a face run does not import them
_BUILDERS = {"face": lambda: FACE, "arm": _arm, "keyframe": _keyframe}
_BUILT: dict[str, Pipeline] = {"face": FACE}


def __getattr__(name: str) -> Pipeline:
    """``ARM`` and ``KEYFRAME``, built on first access."""
    if name in ("ARM", "KEYFRAME"):
        return get_pipeline(name.lower())
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def get_pipeline(name: str) -> Pipeline:
    """A pipeline by name (``face``...) or by import path ``package.module:ATTRIBUTE``
    (importable from the working directory too); ValueError saying what is wrong otherwise."""
    if ":" in name:
        module, attr = name.split(":", 1)
        if os.getcwd() not in sys.path:
            sys.path.append(os.getcwd())
        try:
            found = getattr(importlib.import_module(module), attr)
        except ImportError as exc:
            raise ValueError(f"-p {name}: cannot import {module!r}: {exc}") from None
        except AttributeError:
            raise ValueError(f"-p {name}: module {module!r} has no {attr!r}") from None
        if not isinstance(found, Pipeline):
            raise ValueError(
                f"-p {name}: {attr!r} is a {type(found).__name__}, not a physanim.pipeline.Pipeline"
            )
        return found
    if name not in _BUILDERS:
        raise ValueError(f"unknown pipeline {name!r}; known: {', '.join(_BUILDERS)}")
    if name not in _BUILT:
        _BUILT[name] = _BUILDERS[name]()
    return _BUILT[name]

"""Decide, without running anything, which stages are cached and which will run, and why."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import BaseModel

from physanim.pipeline.spec import DatasetParams, Pipeline, PipelineConfig, StageSpec
from physanim.store import StageStore, stage_key

Action = Literal["cached", "run", "skip"]


@dataclass(frozen=True)
class PlanEntry:
    """What ``run`` will do for one stage: ``cached`` (reuse), ``run`` or ``skip`` (unselected).

    ``damage``: what is wrong with a damaged output found at this key (it is moved aside and
    recomputed), else empty.
    """

    stage: str
    key: str
    action: Action
    reason: str
    upstream: Mapping[str, str]
    params: Mapping[str, Any]
    forced: bool = False
    damage: str = ""


def key_params(spec: StageSpec, dataset: DatasetParams, params: BaseModel) -> dict[str, Any]:
    """The params that enter the stage key: validated params plus the input fingerprint."""
    out: dict[str, Any] = {"params": params.model_dump(mode="json")}
    if spec.fingerprint is not None:
        out["inputs"] = dict(spec.fingerprint(dataset, params))
    return out


def _flat(tree: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(tree, Mapping):
        out: dict[str, Any] = {}
        for k, v in tree.items():
            out.update(_flat(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: tree}


def _why(
    spec: StageSpec, store: StageStore, params: Mapping[str, Any], upstream: Mapping[str, str]
) -> str:
    """Human reason why the stage's key has no output, against its latest output."""
    latest = store.latest(spec.name)
    if latest is None:
        return "no output yet"
    prev = store.provenance(spec.name, latest)
    reasons = []
    if prev.get("version") != spec.version:
        reasons.append(f"code version {prev.get('version')} -> {spec.version}")
    old, new = _flat(prev.get("key_params", {}), ""), _flat(dict(params), "")
    for k in sorted(set(old) | set(new)):
        if old.get(k) != new.get(k):
            section = spec.section or spec.name  # as the user writes it in a config
            label = f"{section}.{k.removeprefix('params.')}" if k.startswith("params.") else k
            reasons.append(f"{label}: {old.get(k, '(unset)')!r} -> {new.get(k, '(unset)')!r}")
    changed = [u for u, key in upstream.items() if prev.get("upstream", {}).get(u) != key]
    if changed:
        reasons.append("upstream changed: " + ", ".join(changed))
    return "; ".join(reasons) or "output removed"


def make_plan(
    pipeline: Pipeline,
    config: PipelineConfig,
    store: StageStore,
    *,
    only: str | None = None,
    start: str | None = None,
    force: Iterable[str] = (),
    checksums: bool = False,
) -> list[PlanEntry]:
    """Plan a run of ``pipeline`` with ``config``.

    ``only``: run just that stage (its upstream must be cached).  ``start`` (CLI ``--from``):
    run that stage and its downstream, reusing cached upstream.  ``force``: recompute these
    stages and their downstream even when cached.  Stages outside the selection are ``skip``
    when not cached.  A damaged output is not cached; ``checksums`` also verifies the
    checksums of every cached output (``status --verify``), not only its files' sizes.
    """
    if only and start:
        raise ValueError("use --only or --from, not both")
    if only:
        selected = {pipeline.stage(only).name}
    elif start:
        selected = set(pipeline.downstream(pipeline.stage(start).name))
    else:
        selected = {s.name for s in pipeline.stages}
    forced: set[str] = set()
    for f in force:
        forced.update(pipeline.downstream(pipeline.stage(f).name))

    dataset = config.dataset
    keys: dict[str, str] = {}
    entries: list[PlanEntry] = []
    for spec in pipeline.stages:
        params = key_params(spec, dataset, spec.params_from(config))
        upstream = {u: keys[u] for u in spec.upstream}
        try:
            key = keys[spec.name] = stage_key(spec.name, spec.version, params, upstream)
        except ValueError as exc:
            raise ValueError(f"{spec.name}.{str(exc).removeprefix('params.')}") from None
        damage = store.damage(spec.name, key, checksums=checksums) or ""
        cached = not damage and store.has(spec.name, key)
        if spec.name not in selected:
            action: Action = "cached" if cached else "skip"
            reason = "not selected" + ("" if cached else " (and not computed)")
        elif spec.name in forced:
            action, reason = "run", "forced"
        elif cached:
            action, reason = "cached", "same params, code version and inputs"
        else:
            action, reason = "run", _why(spec, store, params, upstream)
        if damage:
            reason = f"damaged: {damage}" if action == "run" else f"{reason}; damaged: {damage}"
        entries.append(
            PlanEntry(spec.name, key, action, reason, upstream, params, spec.name in forced, damage)
        )

    by_name = {e.stage: e for e in entries}
    for e in entries:
        if e.action == "run":
            blocked = [by_name[u] for u in e.upstream if by_name[u].action == "skip"]
            if blocked:
                what = "; ".join(
                    f"{b.stage} is damaged ({b.damage})"
                    if b.damage
                    else f"{b.stage} has no output for this config"
                    for b in blocked
                )
                raise ValueError(
                    f"stage {e.stage} needs {', '.join(b.stage for b in blocked)}: {what}; "
                    "run without --only (or with --from "
                    f"{blocked[0].stage}) to compute it first"
                )
    return entries

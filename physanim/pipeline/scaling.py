"""Predicted wall time of a sweep on N workers, from measured stage times and the DAG.

A sweep of V variants runs the shared upstream stages once (they form the serial part: each
needs the one before it) and then, per variant, the stages that differ (a chain here:
materials -> simulate -> evaluate -> render).  ``schedule`` plays a work-conserving list
scheduler over those jobs: whenever a worker is free it takes the ready job with the longest
path to the end of the DAG (so the longest chains start first), every job costing its stage
time plus a per-job overhead (Prefect's task engine, Dask's dispatch).  ``predict_wall`` adds
the sweep's fixed cost (cluster start, planning, report).  ``fit_overheads`` measures the
fixed and per-job costs from a real run's stage timeline.
"""

from __future__ import annotations

import heapq
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from physanim.pipeline.runner import StageResult


@dataclass(frozen=True)
class TimedJob:
    """One job of a sweep: its name, its compute time (s) and the names of the jobs it needs."""

    name: str
    seconds: float
    deps: tuple[str, ...] = ()


def sweep_jobs(
    shared: Mapping[str, float],
    per_variant: Mapping[str, float],
    upstream: Mapping[str, Sequence[str]],
    variants: int,
) -> list[TimedJob]:
    """The jobs of a sweep of ``variants`` variants: the ``shared`` stages once and the
    ``per_variant`` stages for each variant (stage -> seconds); ``upstream``: stage -> the
    stages it reads (the DAG)."""
    jobs = [TimedJob(s, t, tuple(upstream.get(s, ()))) for s, t in shared.items()]
    for v in range(variants):

        def name(stage: str, v: int = v) -> str:
            return f"{stage}#{v}" if stage in per_variant else stage

        jobs += [
            TimedJob(name(s), t, tuple(name(u) for u in upstream.get(s, ())))
            for s, t in per_variant.items()
        ]
    return jobs


def _children(jobs: Sequence[TimedJob]) -> dict[str, list[str]]:
    """job -> the jobs that need it."""
    children: dict[str, list[str]] = {j.name: [] for j in jobs}
    for j in jobs:
        for d in j.deps:
            children[d].append(j.name)
    return children


def _tails(jobs: Sequence[TimedJob], overhead_s: float) -> dict[str, float]:
    """Longest path (s) from the start of each job to the end of the DAG."""
    order = _topological(jobs)  # refuses unknown deps and cycles first
    children = _children(jobs)
    tail: dict[str, float] = {}
    for j in reversed(order):
        below = max((tail[c] for c in children[j.name]), default=0.0)
        tail[j.name] = j.seconds + overhead_s + below
    return tail


def _topological(jobs: Sequence[TimedJob]) -> list[TimedJob]:
    by_name = {j.name: j for j in jobs}
    missing = {d for j in jobs for d in j.deps} - set(by_name)
    if missing:
        raise ValueError(f"jobs depend on unknown jobs {sorted(missing)}")
    order: list[TimedJob] = []
    done: set[str] = set()
    pending = list(jobs)
    while pending:
        ready = [j for j in pending if set(j.deps) <= done]
        if not ready:
            raise ValueError(f"the jobs form a cycle: {sorted(j.name for j in pending)}")
        order += ready
        done |= {j.name for j in ready}
        pending = [j for j in pending if j.name not in done]
    return order


def schedule(jobs: Sequence[TimedJob], workers: int, overhead_s: float = 0.0) -> float:
    """Makespan (s) of the jobs on ``workers`` workers, each job taking its seconds plus
    ``overhead_s``; a free worker takes the ready job with the longest path to the end."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    tail, children = _tails(jobs, overhead_s), _children(jobs)
    waiting = {j.name: set(j.deps) for j in jobs}
    cost = {j.name: j.seconds + overhead_s for j in jobs}
    order = {j.name: i for i, j in enumerate(jobs)}
    ready = [(-tail[n], order[n], n) for n, deps in waiting.items() if not deps]
    heapq.heapify(ready)
    running: list[tuple[float, str]] = []  # (finish time, job)
    now, free = 0.0, workers
    while ready or running:
        while ready and free:
            _, _, name = heapq.heappop(ready)
            heapq.heappush(running, (now + cost[name], name))
            free -= 1
        now, name = heapq.heappop(running)
        free += 1
        for c in children[name]:
            waiting[c].discard(name)
            if not waiting[c]:
                heapq.heappush(ready, (-tail[c], order[c], c))
    return now


def predict_wall(
    jobs: Sequence[TimedJob], workers: int, fixed_s: float = 0.0, overhead_s: float = 0.0
) -> float:
    """Wall time (s) of a sweep: its fixed cost plus the makespan of its jobs."""
    return fixed_s + schedule(jobs, workers, overhead_s)


def fit_overheads(
    results: Sequence[StageResult], called: float, returned: float
) -> tuple[float, float]:
    """(fixed s, per-job overhead s) of a measured sweep on one worker: the time before the
    first stage started and after the last one ended, and the gaps between consecutive
    stages averaged over the jobs. ``called``/``returned``: Unix times (s) around the run."""
    ran = sorted((r for r in results if r.action == "ran"), key=lambda r: r.started)
    if not ran:
        raise ValueError("no stage ran: nothing to fit")
    if len({r.worker for r in ran}) != 1:
        raise ValueError("fit the overheads on a one-worker run (its gaps are pure overhead)")
    first, last = ran[0].started, max(r.started + r.seconds for r in ran)
    gaps = (last - first) - sum(r.seconds for r in ran)
    return (first - called) + (returned - last), max(0.0, gaps) / len(ran)

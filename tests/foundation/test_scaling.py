"""The sweep scaling model: list-scheduling makespans against hand-computed answers, and the
overheads fitted from a one-worker timeline reproduce that run's wall time."""

from __future__ import annotations

import math

import pytest

from physanim.pipeline import StageResult
from physanim.pipeline.scaling import (
    TimedJob,
    fit_overheads,
    predict_wall,
    schedule,
    sweep_jobs,
)

#: The face DAG's shape: a shared chain, then one chain per variant
UPSTREAM = {"tetra": ["align"], "materials": ["tetra"], "simulate": ["materials", "tetra"]}


@pytest.mark.parametrize("jobs, workers", [(7, 1), (7, 2), (7, 3), (7, 7), (7, 64)])
def test_independent_jobs_take_ceil_of_jobs_over_workers(jobs: int, workers: int) -> None:
    independent = [TimedJob(f"j{i}", 2.0) for i in range(jobs)]
    assert schedule(independent, workers) == 2.0 * math.ceil(jobs / workers)


def test_a_chain_does_not_speed_up() -> None:
    chain = [TimedJob("a", 1.0), TimedJob("b", 2.0, ("a",)), TimedJob("c", 4.0, ("b",))]
    assert schedule(chain, 1) == schedule(chain, 16) == 7.0
    assert schedule(chain, 16, overhead_s=0.5) == 8.5


def test_shared_stages_are_the_serial_part() -> None:
    jobs = sweep_jobs(
        {"align": 6.0, "tetra": 4.0}, {"materials": 1.0, "simulate": 4.0}, UPSTREAM, 4
    )
    assert len(jobs) == 2 + 4 * 2
    assert schedule(jobs, 1) == 10.0 + 4 * 5.0
    assert schedule(jobs, 2) == 10.0 + 2 * 5.0
    assert schedule(jobs, 4) == schedule(jobs, 64) == 10.0 + 5.0  # one chain per worker
    # 3 workers, 0.5 s per job: shared 6.5 + 4.5; materials #0-2 to 1.5 s; then materials #3
    # (longest path left) and simulate #0, #1; simulate #2 at 3.0 s, #3 at 6.0 s, ends 10.5 s
    assert predict_wall(jobs, 3, fixed_s=2.0, overhead_s=0.5) == 2.0 + 11.0 + 10.5


def test_the_longest_path_starts_first() -> None:
    """Two workers: the 3-job chain starts before the lone 2 s jobs (FIFO would take 5 s)."""
    jobs = [
        TimedJob("x", 2.0),
        TimedJob("y", 2.0),
        TimedJob("a", 1.0),
        TimedJob("b", 1.0, ("a",)),
        TimedJob("c", 1.0, ("b",)),
    ]
    assert schedule(jobs, 2) == 4.0


def test_bad_dags_are_refused() -> None:
    with pytest.raises(ValueError, match="unknown jobs"):
        schedule([TimedJob("a", 1.0, ("z",))], 2)
    with pytest.raises(ValueError, match="cycle"):
        schedule([TimedJob("a", 1.0, ("b",)), TimedJob("b", 1.0, ("a",))], 2)


def test_fitted_overheads_reproduce_the_one_worker_run() -> None:
    """A one-worker timeline: 3 s before the first stage, gaps of 0.4 s, 2 s after."""
    seconds = [5.0, 1.0, 3.0, 2.0]
    results, t = [], 103.0
    for i, s in enumerate(seconds):
        results.append(StageResult(f"s{i}", "k", "ran", s, {}, t, "host:1"))
        t += s + 0.4
    returned = t - 0.4 + 2.0
    fixed, per_job = fit_overheads(results, 100.0, returned)
    assert fixed == pytest.approx(5.0) and per_job == pytest.approx(0.3)  # 3 gaps over 4 jobs
    chain = [TimedJob(f"s{i}", s, (f"s{i - 1}",) if i else ()) for i, s in enumerate(seconds)]
    assert predict_wall(chain, 1, fixed, per_job) == pytest.approx(returned - 100.0)
    two = [*results[:2], StageResult("s2", "k", "ran", 3.0, {}, 104.0, "host:2")]
    with pytest.raises(ValueError, match="one-worker"):
        fit_overheads(two, 100.0, 120.0)

"""Reduced (POD) previews of material edits (``simulate.reduced.enabled: true``).

A material edit changes only the per-tet materials: the mesh, the drive and the boundary
conditions stay. So one full run of a *basis material* (``ReducedParams.basis_model``, default
the seed's uniform model) gives a POD basis (its displacement snapshots plus their
sensitivities to each region's stiffness and viscosity, :mod:`physanim.fem.reduced`), and every
material variant is previewed in that basis in seconds.

The basis is kept in a :class:`~physanim.store.file_cache.FileCache` folder, keyed by the
content of everything it depends on (mesh, boundary conditions, region labels, the basis
material, the full-run and reduced settings), so every variant of a sweep reuses it; a file
lock keeps parallel sweep workers from building it twice.
"""

from __future__ import annotations

import fcntl
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from physanim.fem import reduced
from physanim.fem.model import build_model
from physanim.fem.params import SimulateParams
from physanim.fem.problem import FemProblem
from physanim.fem.region_materials import tet_materials
from physanim.fem.simulate import SimResult, simulate_problem
from physanim.fem.statics import free_dofs
from physanim.mesh.params import UNIFORM, MaterialModel
from physanim.store.file_cache import FileCache, content_digest

#: bumped by hand when the basis' numerics change (part of its cache key)
BASIS_VERSION = "3"
#: bases kept in the cache (the most recently used; about 20 MB each on the demo)
KEEP = 4


class ReducedParams(BaseModel):
    """Reduced (POD) preview of the FEM run; off by default (the full FEM runs)."""

    model_config = ConfigDict(extra="forbid")
    enabled: bool = Field(False, description="preview in a POD basis instead of the full FEM")
    basis_model: MaterialModel | None = Field(
        None,
        description="material model of the full run that makes the basis (a materials "
        "file's 'model' section); null: the uniform model",
    )
    energy: float = Field(
        0.999999,
        gt=0.0,
        lt=1.0,
        description="share of the basis snapshots' squared norm the modes keep (dimensionless)",
    )
    max_modes: int = Field(150, ge=1, le=1000, description="most modes in the basis")
    sensitivity_modes: int = Field(
        20,
        ge=0,
        le=200,
        description="leading displacement and velocity modes of the basis run whose "
        "sensitivities to each region's E and eta join the snapshots (0: snapshots only)",
    )
    estimate: bool = Field(
        False,
        description="estimate the preview's error from the full model's residual (one "
        "factorisation, seconds); benchmarks/bench_reduced.py measures it against full runs",
    )

    @property
    def basis_material(self) -> MaterialModel:
        """The basis material model (the uniform model when unset)."""
        return self.basis_model or UNIFORM


@dataclass(frozen=True)
class PreviewBasis:
    """A POD basis and what made it: ``basis`` (modes over the free DOFs), ``substeps`` (T,)
    of the basis run per frame (the preview steps the same), the basis material's own preview
    error against its full run (``error_peak`` / ``error_rms``, shares of the peak
    displacement), build time ``seconds``, whether it came from the cache, its cache ``key``."""

    basis: reduced.PodBasis
    substeps: np.ndarray
    error_peak: float
    error_rms: float
    seconds: float
    cached: bool
    key: str


def basis_key(
    problem: FemProblem, tet_labels: np.ndarray, params: SimulateParams, settings: ReducedParams
) -> str:
    """Content key of a basis: code version, mesh, conditions, region labels, basis material,
    full-run settings (the :class:`SimulateParams` fields of ``params``) and the reduced
    settings that shape the basis."""
    bc, act = problem.conditions, problem.actuation
    springs = bc.springs
    spring_parts = () if springs is None else (springs.nodes, springs.stiffness, springs.targets)
    active = (
        ()
        if act is None
        else (act.basis.centres, act.basis.lift, act.basis.radius, act.coefficients)
    )
    shaping = settings.model_dump(mode="json", exclude={"enabled", "estimate"})
    return content_digest(
        BASIS_VERSION, problem.nodes, problem.tets, bc.driven_idx, bc.fixed_idx, bc.values,
        bc.frame_dt, *spring_parts, *active, np.asarray(tet_labels),
        settings.basis_material.model_dump(),
        params.model_dump(mode="json", include=set(SimulateParams.model_fields)), shaping,
    )  # fmt: skip


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive lock on ``path`` (created) while the block runs."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def build_basis(
    problem: FemProblem, tet_labels: np.ndarray, params: SimulateParams, settings: ReducedParams
) -> dict[str, np.ndarray]:
    """Full run of the basis material, its snapshots plus region sensitivities, the POD basis
    and the basis material's own preview error, as arrays (what the cache stores)."""
    labels = np.asarray(tet_labels)
    mats = tet_materials(labels, settings.basis_material)
    basis_problem = problem.with_materials(mats)
    run = simulate_problem(basis_problem, params)
    model = build_model(problem.nodes, problem.tets, mats, params)
    bc = problem.conditions
    extra = None
    if settings.sensitivity_modes:
        rebuild = lambda m: build_model(problem.nodes, problem.tets, m, params)  # noqa: E731
        extra = reduced.material_sensitivities(
            model, bc, run.displacements, run.times, labels, rebuild, mats,
            settings.sensitivity_modes, params.solver,
        )  # fmt: skip
    free = free_dofs(model.n_dofs, bc.prescribed_dofs)
    basis = reduced.pod_basis(run.displacements, free, settings.energy, settings.max_modes, extra)
    own = reduced.simulate_reduced(
        model, bc, basis, run.frame_substeps, actuation=problem.actuation
    )
    error = reduced.displacement_error(own.result.displacements, run.displacements)
    return {
        "phi": basis.phi,
        "free": basis.free,
        "singular_values": basis.singular_values,
        "substeps": run.frame_substeps,
        "basis_error_peak": np.float64(error["peak"]),
        "basis_error_rms": np.float64(error["rms"]),
    }


def _read(path: Path) -> dict[str, np.ndarray] | None:
    """A cached basis, or None when absent or unreadable (then rebuilt)."""
    try:
        with np.load(path) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError):
        return None


def load_or_build_basis(
    problem: FemProblem,
    tet_labels: np.ndarray,
    params: SimulateParams,
    settings: ReducedParams,
    cache_dir: Path,
) -> PreviewBasis:
    """The basis of ``problem``'s mesh and conditions from ``cache_dir``, built under a lock
    when missing or unreadable; the ``KEEP`` most recently used bases stay."""
    key = basis_key(problem, tet_labels, params, settings)
    cache = FileCache(cache_dir, keep=KEEP)
    t0 = time.perf_counter()
    with _locked(cache.folder / f".{key[:32]}.lock"):  # hidden: the cache does not count it
        found = cache.fetch(key, ".npz")
        out = None if found is None else _read(found)
        cached = out is not None
        if out is None:
            out = build_basis(problem, tet_labels, params, settings)
            built = out
            cache.put(key, ".npz", lambda path: np.savez(path, **built))
    return PreviewBasis(
        basis=reduced.PodBasis(out["phi"], out["free"], out["singular_values"]),
        substeps=out["substeps"],
        error_peak=float(out["basis_error_peak"]),
        error_rms=float(out["basis_error_rms"]),
        seconds=time.perf_counter() - t0,
        cached=cached,
        key=key,
    )


def preview(
    problem: FemProblem,
    tet_labels: np.ndarray,
    region_names: list[str],
    params: SimulateParams,
    settings: ReducedParams,
    cache_dir: Path,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[SimResult, dict[str, Any]]:
    """The reduced run of ``problem`` (a material variant) and its summary: basis size and
    energy, the basis material's exact error, and with ``settings.estimate`` this variant's
    error estimated from the full model's residual (shares of the peak displacement, %)."""
    found = load_or_build_basis(problem, tet_labels, params, settings, cache_dir)
    t0 = time.perf_counter()
    model = build_model(problem.nodes, problem.tets, problem.materials, params)
    t_asm = time.perf_counter() - t0
    bc = problem.conditions
    run = reduced.simulate_reduced(
        model, bc, found.basis, found.substeps, progress, problem.actuation
    )
    result = run.result
    summary: dict[str, Any] = {
        "modes": found.basis.size,
        "energy_captured": round(found.basis.energy, 9),
        "basis_model": settings.basis_material.name,
        "basis_key": found.key[:12],
        "basis_cached": found.cached,
        "basis_error_peak_pct": round(100 * found.error_peak, 4),
        "basis_error_rms_pct": round(100 * found.error_rms, 4),
    }
    seconds = {"basis": found.seconds, "assembly": t_asm, **result.timings}
    if settings.estimate:
        t0 = time.perf_counter()
        est = reduced.residual_estimate(
            model, bc, found.basis, run, params.solver, problem.actuation
        )
        seconds["estimate"] = time.perf_counter() - t0
        # |(u + e) - u| against u: the estimated error relative to the preview's own size
        pair = (result.displacements + est, result.displacements)
        error = reduced.displacement_error(*pair)
        regions = reduced.region_errors(*pair, problem.tets, tet_labels, region_names)
        summary.update(
            error="estimate: full-model residual of the preview",
            error_peak_pct=round(100 * error["peak"], 4),
            error_rms_pct=round(100 * error["rms"], 4),
            error_peak_pct_by_region={k: round(100 * v, 4) for k, v in regions.items()},
        )
    else:
        summary["error"] = "not estimated (simulate.reduced.estimate: true estimates it)"
    summary["seconds"] = {k: round(v, 3) for k, v in seconds.items()}
    return result, summary

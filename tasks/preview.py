"""The ``simulate`` stage's reduced preview (``simulate.reduced.enabled: true``).

A material edit changes only the ``materials`` stage's output: the mesh, the drive and the
boundary conditions stay. So one full run of a *basis material* (``reduced.basis_model``,
default the uniform model) gives a POD basis (its displacement snapshots plus their
sensitivities to each region's stiffness and viscosity, ``physanim.fem.reduced``), and every
material variant is previewed in that basis in seconds.

The basis lives in ``<run dir>/cache/reduced-basis/`` (a ``FileCache``), keyed by everything it
depends on: the simulate code version and full-run params, the reduced settings, the track,
align and tetra keys and the variant's region labels. The basis run is the store's own
``simulate`` output for the basis material when there is one; otherwise it is computed once
(a file lock keeps parallel sweep workers from computing it twice). The preview's key is the
simulate stage's key, which holds the reduced settings and the same upstream keys, so it
changes whenever the basis would.
"""

from __future__ import annotations

import fcntl
import hashlib
import time
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from physanim.mesh.params import MaterialModel

#: bumped by hand when the basis' numerics change (part of its cache key)
BASIS_VERSION = "1"

if TYPE_CHECKING:
    from collections.abc import Iterator

    from physanim.fem.simulate import SimResult
    from physanim.pipeline import StageContext
    from tasks.materials import MaterialsOutput


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
        description="when the store holds no full run of this variant, estimate the "
        "preview's error from the full model's residual (one factorisation, seconds)",
    )


def _key(ctx: StageContext[Any], materials: MaterialsOutput) -> str:
    """Content key of the basis: code version, full-run params, reduced settings, upstream
    keys of track, align and tetra, and the region labels."""
    from physanim.store.keys import canonical_json

    params = ctx.params.model_dump(mode="json")
    reduced = params.pop("reduced")
    reduced.pop("enabled"), reduced.pop("estimate")
    payload = {
        "basis": BASIS_VERSION,
        "version": ctx.spec.version,
        "params": params,
        "reduced": reduced,
        "upstream": {s: ctx.upstream[s] for s in ("track", "align", "tetra")},
        "labels": hashlib.sha256(np.ascontiguousarray(materials.tet_labels).tobytes()).hexdigest(),
    }
    return hashlib.sha256(canonical_json(payload).encode("ascii")).hexdigest()


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


def full_run_key(ctx: StageContext[Any], upstream: dict[str, str]) -> str:
    """The simulate key of a full run with this stage's params and ``upstream`` keys."""
    from physanim.pipeline.plan import key_params
    from physanim.store import stage_key

    full = ctx.params.model_copy(update={"reduced": ReducedParams()})
    return stage_key(
        "simulate", ctx.spec.version, key_params(ctx.spec, ctx.dataset, full), upstream
    )


def _basis_run(ctx: StageContext[Any], args: dict[str, Any], basis_materials: Any) -> Any:
    """The full run of the basis material: the store's simulate output if present (its
    materials key recomputed from the variant's region settings), else computed here."""
    from physanim.fem.simulate import simulate
    from physanim.pipeline.plan import key_params
    from physanim.store import read_dataclass, stage_key
    from tasks import materials as materials_stage
    from tasks.simulate import SimulateOutput

    mat_params = ctx.upstream_params("materials", materials_stage.MaterialsStageParams)
    mat_params = mat_params.model_copy(update={"model": basis_model(ctx.params.reduced)})
    mat_upstream = ctx.store.provenance("materials", ctx.upstream["materials"])["upstream"]
    mat_key = stage_key(
        "materials",
        materials_stage.SPEC.version,
        key_params(materials_stage.SPEC, ctx.dataset, mat_params),
        mat_upstream,
    )
    key = full_run_key(ctx, {**ctx.upstream, "materials": mat_key})
    if ctx.store.has("simulate", key):
        return read_dataclass(SimulateOutput, ctx.store.open("simulate", key)), key
    return simulate(**{**args, "materials": basis_materials}, params=ctx.params), None


def basis_model(params: ReducedParams) -> MaterialModel:
    """The basis material model (the uniform model when unset)."""
    from tasks.materials import UNIFORM

    return params.basis_model or UNIFORM


#: bases kept in the cache (the most recently used; about 20 MB each on the demo)
KEEP = 4


def load_or_build_basis(
    ctx: StageContext[Any], args: dict[str, Any], materials: MaterialsOutput
) -> dict[str, Any]:
    """The basis (``phi``, ``free``, ``singular_values``, ``substeps``, exact error of the
    basis material's own preview ``basis_error_peak``/``_rms``, ``basis_run``, ``seconds``)
    from the cache, built under a lock when missing or unreadable; the ``KEEP`` most recently
    used bases stay."""
    from physanim.store.file_cache import FileCache

    key = _key(ctx, materials)
    cache = FileCache(ctx.dataset.run_dir / "cache" / "reduced-basis", keep=KEEP)
    with _locked(cache.folder / f".{key[:32]}.lock"):  # hidden: the cache does not count it
        found = cache.fetch(key, ".npz")
        out = None if found is None else _read(found)
        cached = out is not None
        if out is None:
            t0 = time.perf_counter()
            built = _build(ctx, args, materials)
            built["seconds"] = np.float64(time.perf_counter() - t0)
            cache.put(key, ".npz", lambda path: np.savez(path, **built))
            out = built
    out["cached"], out["key"] = cached, key
    return out


def _read(path: Path) -> dict[str, Any] | None:
    """A cached basis, or None when absent or unreadable (then rebuilt)."""
    try:
        with np.load(path) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError):
        return None


def _build(ctx: StageContext[Any], args: dict[str, Any], materials: MaterialsOutput) -> dict:
    """Full run of the basis material (or the store's), its snapshots plus region
    sensitivities, the POD basis, and the basis material's own preview against its run."""
    from physanim.fem import reduced
    from physanim.fem.model import build_model
    from physanim.fem.region_materials import tet_materials
    from physanim.fem.statics import free_dofs

    params = ctx.params
    mats = tet_materials(materials.tet_labels, basis_model(params.reduced))
    run, stored_key = _basis_run(ctx, args, mats)
    model = build_model(args["nodes"], args["tets"], mats, params)
    bc = conditions(args)
    rebuild = lambda m: build_model(args["nodes"], args["tets"], m, params)  # noqa: E731
    extra = None
    if params.reduced.sensitivity_modes:
        extra = reduced.material_sensitivities(
            model, bc, run.displacements, run.times, materials.tet_labels, rebuild, mats,
            params.reduced.sensitivity_modes, params.solver,
        )  # fmt: skip
    free = free_dofs(model.n_dofs, bc.prescribed_dofs)
    basis = reduced.pod_basis(
        run.displacements, free, params.reduced.energy, params.reduced.max_modes, extra
    )
    preview = reduced.simulate_reduced(model, bc, basis, run.frame_substeps)
    error = reduced.displacement_error(preview.result.displacements, run.displacements)
    return {
        "phi": basis.phi,
        "free": basis.free,
        "singular_values": basis.singular_values,
        "substeps": run.frame_substeps,
        "basis_error_peak": np.float64(error["peak"]),
        "basis_error_rms": np.float64(error["rms"]),
        "basis_run": np.str_(stored_key or "computed for the basis"),
    }


def conditions(args: dict[str, Any]) -> Any:
    """The :class:`~physanim.fem.boundary.BoundaryConditions` of ``simulate``'s arguments."""
    from physanim.fem.boundary import BoundaryConditions

    return BoundaryConditions.checked(
        len(args["nodes"]), args["driven_idx"], args["driven_traj"], args["frame_dt"],
        args.get("fixed_idx"), args["springs"],
    )  # fmt: skip


def preview(
    ctx: StageContext[Any], args: dict[str, Any], materials: MaterialsOutput
) -> tuple[SimResult, dict[str, Any]]:
    """The reduced run of this variant and its summary: basis size, energy, the basis
    material's exact error, and this variant's error against its full run in the store
    (exact) or, with ``reduced.estimate``, from the residual (an estimate)."""
    from physanim.fem import reduced
    from physanim.fem.model import build_model
    from physanim.store import read_dataclass
    from tasks.simulate import SimulateOutput

    params = ctx.params
    t0 = time.perf_counter()
    stored = load_or_build_basis(ctx, args, materials)
    t_basis = time.perf_counter() - t0
    basis = reduced.PodBasis(stored["phi"], stored["free"], stored["singular_values"])
    t0 = time.perf_counter()
    model = build_model(args["nodes"], args["tets"], args["materials"], params)
    t_asm = time.perf_counter() - t0
    bc = conditions(args)
    run = reduced.simulate_reduced(
        model, bc, basis, stored["substeps"], progress=ctx.progress("simulate (reduced)")
    )
    result = run.result
    summary: dict[str, Any] = {
        "modes": basis.size,
        "energy_captured": round(basis.energy, 9),
        "basis_model": basis_model(params.reduced).name,
        "basis_run": str(stored["basis_run"]),
        "basis_cached": bool(stored["cached"]),
        "basis_error_peak_pct": round(100 * float(stored["basis_error_peak"]), 4),
        "basis_error_rms_pct": round(100 * float(stored["basis_error_rms"]), 4),
    }
    full_key = full_run_key(ctx, dict(ctx.upstream))
    seconds = {"basis": t_basis, "assembly": t_asm, **result.timings}
    pair = None  # (displacements, reference) whose difference is the error
    if ctx.store.has("simulate", full_key):
        full = read_dataclass(SimulateOutput, ctx.store.open("simulate", full_key))
        pair = (result.displacements, full.displacements)
        summary["error"] = "exact: against this variant's full run " + full_key[:12]
    elif params.reduced.estimate:
        t0 = time.perf_counter()
        est = reduced.residual_estimate(model, bc, basis, run, params.solver)
        seconds["estimate"] = time.perf_counter() - t0
        # |(u + e) - u| against u: the estimated error relative to the preview's own size
        pair = (result.displacements + est, result.displacements)
        summary["error"] = "estimate: full-model residual of the preview (no full run stored)"
    else:
        summary["error"] = (
            "not measured: no full run of this variant in the store "
            "(simulate.reduced.estimate: true estimates it)"
        )
    if pair is not None:
        error = reduced.displacement_error(*pair)
        summary["error_peak_pct"] = round(100 * error["peak"], 4)
        summary["error_rms_pct"] = round(100 * error["rms"], 4)
        regions = reduced.region_errors(
            *pair, args["tets"], materials.tet_labels, materials.region_names
        )
        summary["error_peak_pct_by_region"] = {k: round(100 * v, 4) for k, v in regions.items()}
    summary["seconds"] = {k: round(v, 3) for k, v in seconds.items()}
    return result, summary

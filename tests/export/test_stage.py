"""The export stage on the session's coarse face demo (``face_demo``): its files hold the
run's FEM skin and captured scan, and ``physanim show export`` says where they are."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from pxr import Usd, UsdGeom

from flows.dags import FACE
from physanim.config import load_config
from physanim.export.gltf import read_glb, rms_distance
from physanim.export.usd import ROOT as USD_ROOT
from physanim.mesh.embed import embedded_displacements
from physanim.store import StageStore, read_dataclass
from tasks.align import AlignOutput
from tasks.dense import DenseOutput
from tasks.export import ExportOutput
from tasks.simulate import SimulateOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput
from tests.commands import ROOT, physanim
from tests.conftest import COARSE


def stored_motion(data: Path) -> tuple[Any, dict[str, np.ndarray], ExportOutput]:
    """The coarse demo run in ``data``: its config, each exported variant's motion (T, N, 3) m
    from the stored upstream outputs (without the stage's embedding cache), and the export
    stage's output."""
    cfg, _ = load_config(
        FACE.config_model(), [FACE.default_config, ROOT / COARSE], [f"dataset.dir={ROOT / data}"]
    )
    store = StageStore(cfg.dataset.store_path)
    align = read_dataclass(AlignOutput, store.open("align"))
    tetra = read_dataclass(TetraOutput, store.open("tetra"))
    simulate = read_dataclass(SimulateOutput, store.open("simulate"))
    scan = align.scan_vertices
    expected = {
        "fem": scan
        + embedded_displacements(
            scan, align.scan_side, tetra.nodes, tetra.tets, align.mouth(), simulate.displacements
        ),
        "capture": read_dataclass(DenseOutput, store.open("dense")).motion[...],
    }
    return cfg, expected, read_dataclass(ExportOutput, store.open("export"))


def test_the_files_hold_the_runs_motion(face_demo: tuple[Path, str]) -> None:
    data, _ = face_demo
    cfg, expected, out = stored_motion(data)
    fps = read_dataclass(TrackOutput, StageStore(cfg.dataset.store_path).open("track")).fps
    assert out.variants == ["fem", "capture"] and out.fps == fps
    show = physanim("show", "export", "--dataset", str(data), "-c", COARSE)
    assert show.returncode == 0, show.stderr
    files = json.loads(show.stdout)["files"]
    folder = Path(files["folder"])
    assert (
        sorted(files["plain"])
        == sorted(out.files)
        == sorted(f"{v}.{s}" for v in expected for s in ("usdc", "glb"))
    )
    tolerance_mm = cfg.export.gltf_tolerance_mm
    for (name, points), rms_mm in zip(expected.items(), out.gltf_rms_mm, strict=True):
        stage = Usd.Stage.Open(str(folder / f"{name}.usdc"))
        assert stage.GetTimeCodesPerSecond() == fps
        attr = UsdGeom.Mesh(stage.GetPrimAtPath(f"/{USD_ROOT}/{name}")).GetPointsAttr()
        assert attr.GetTimeSamples() == list(range(len(points)))
        for t, frame in enumerate(points):
            np.testing.assert_allclose(np.asarray(attr.Get(t)), frame, rtol=0, atol=1e-6)
        decoded = read_glb(folder / f"{name}.glb").positions()
        assert rms_distance(decoded, points) * 1e3 <= tolerance_mm
        assert abs(rms_distance(decoded, points) * 1e3 - rms_mm) < 1e-4

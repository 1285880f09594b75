"""A dataset made from a real photo (scikit-image's astronaut) through check, ingest, track
(markerless) and fit in the face DAG, and the clear errors of track and fit on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flows.dags import FACE
from physanim.config import load_config
from physanim.face.landmarks import FEATURE_POINTS
from physanim.face.params import FitParams
from physanim.pipeline import StageFailed, execute_plan_locally, make_plan
from physanim.store import StageStore
from physanim.tracking.dataset_check import check_dataset
from physanim.tracking.markerless import MARKERLESS_POINTS
from tasks.fit import _check_tracked
from tests.capture.photo_dataset import FX, photo_depth, write_photo_dataset

pytest.importorskip("ai_edge_litert", reason="markerless extra not installed")
skdata = pytest.importorskip("skimage.data", reason="scikit-image (real test photo) missing")


def run_until(root: Path, last: str, *sets: str) -> tuple[StageStore, list]:
    """Run the face DAG on ``root`` up to ``last`` (in this process); the results."""
    cfg, _ = load_config(FACE.config_model(), [FACE.default_config], [f"dataset.dir={root}", *sets])
    store = StageStore(cfg.dataset.store_path)
    names = [s.name for s in FACE.stages]
    plan = make_plan(FACE, cfg, store)[: names.index(last) + 1]
    return store, execute_plan_locally(FACE, cfg, plan)


def test_real_photo_through_check_ingest_track_fit(tmp_path: Path) -> None:
    photo = skdata.astronaut()
    root = write_photo_dataset(tmp_path / "astronaut", photo, n_frames=4)
    cfg, _ = load_config(FACE.config_model(), [FACE.default_config], [
        f"dataset.dir={root}", "track.backend=markerless"])  # fmt: skip
    assert check_dataset(root, cfg.ingest, cfg.track).problems == []
    store, results = run_until(root, "fit", "track.backend=markerless")
    assert [(r.stage, r.action) for r in results] == [("ingest", "ran"), ("track", "ran"),
                                                      ("fit", "ran")]  # fmt: skip
    track = store.open("track")
    assert track.attrs["summary"]["tracked_fraction"] == 1.0
    assert track.attrs["summary"]["warnings"] == []
    uv, points = track["uv"][...], track["points"][...]
    assert uv.shape == (4, len(MARKERLESS_POINTS), 2)
    # The photo moves 4 px right and 2 px down per frame: so do the landmarks.
    motion = uv - uv[0]
    expected = np.array([[4 * t, 2 * t] for t in range(4)], float)[:, None, :]
    assert np.sqrt(((motion - expected) ** 2).sum(-1).mean()) < 1.5
    # Their depth is the synthetic surface's under them: 0.60-0.68 m.
    assert np.all((points[..., 2] > 0.59) & (points[..., 2] < 0.69))
    u, v = uv[0, FEATURE_POINTS.index("pronasale")]
    depth = photo_depth(photo.shape[:2], (0, 0), 0.6)
    assert points[0, FEATURE_POINTS.index("pronasale"), 2] == pytest.approx(
        depth[round(v), round(u)], abs=2e-3
    )
    assert points[0, FEATURE_POINTS.index("pronasale"), 0] == pytest.approx(
        (u - 256) / FX * depth[round(v), round(u)], abs=2e-3
    )
    fit = store.open("fit")
    print(f"astronaut: fit residual {fit.attrs['summary']['rms_mm']} mm RMS")
    assert fit.attrs["summary"]["rms_mm"] < 5.0
    assert np.isfinite(fit["au"][...]).all()


@pytest.mark.parametrize(
    ("kwargs", "sets", "message"),
    [
        ({"photo": "coffee"}, ["track.backend=markerless"], r"no face found in any of the 3"),
        (  # 0.25 mm depth units read as mm: a face 3x too large, at a plausible 1.8 m
            {"distance_m": 0.45, "depth_unit_m": 0.00025, "depth_scale_in_json": False},
            ["track.backend=markerless"],
            r"the tracked face is 3\.\d\d x the size of the face model: the depth scale or the "
            r"intrinsics are wrong",
        ),
        (
            {},
            [],
            r"/\S+/ds/ground_truth\.zarr: marker template not found; for a recording without "
            r"painted markers set track\.backend=markerless",
        ),
        (
            {"photo": "coffee"},
            ["track.template=template.json"],
            r"frame 0: 0 painted marker dot\(s\) found.*set track\.backend=markerless",
        ),
        (  # the astronaut's suit has 36 blobs of the markers' colour
            {},
            ["track.template=template.json"],
            r"frame 0: cannot fit the marker template \(3 markers\) to the 36 dots found.*"
            r"set track\.backend=markerless",
        ),
    ],
)
def test_track_refuses_clearly(tmp_path: Path, kwargs: dict, sets: list, message: str) -> None:
    photo = getattr(skdata, kwargs.pop("photo", "astronaut"))()
    root = write_photo_dataset(tmp_path / "ds", photo, n_frames=3, **kwargs)
    template = {"names": ["a", "b", "c"], "positions_m": [[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]]}
    (root / "template.json").write_text(json.dumps(template))
    with pytest.raises(StageFailed, match=r"stage 'track' failed: \w+: " + message):
        run_until(root, "track", *sets)


def test_fit_names_missing_points() -> None:
    params = FitParams()
    points = np.zeros((5, 16, 3))
    conf = np.zeros((5, 16))
    with pytest.raises(ValueError, match=r"no tracked points to fit: no frame .* 3 landmarks"):
        _check_tracked(points, conf, params)
    conf[3:, :4] = 1.0
    with pytest.raises(ValueError, match=r"fit\.neutral_frames=1 .* first tracked at frame 3"):
        _check_tracked(points, conf, params)
    conf[0, :3] = 1.0
    _check_tracked(points, conf, params)

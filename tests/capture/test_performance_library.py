"""The expression fields beyond jaw drop and smile, the performance library and its datasets."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import zarr
from pydantic import ValidationError, create_model
from scipy.spatial.transform import Rotation

from physanim.capture.demo import generate_demo
from physanim.capture.expressions import (
    BrowField,
    CheekPuffField,
    CompositeField,
    JawSideField,
    MouthField,
    NoseWrinkleField,
    face_field,
)
from physanim.capture.library import (
    DEMO,
    HELD_OUT,
    LIBRARY,
    PERFORMANCE_NAMES,
    TUNING,
    dataset_name,
    library_params,
    performance_setup,
)
from physanim.capture.params import DemoParams
from physanim.capture.performance import AnalyticFaceField, demo_performance
from physanim.capture.raster import project
from physanim.evaluate.truth import Truth, load_truth, truth_peaks
from physanim.pipeline import DatasetParams, PipelineConfig
from tasks.ingest import ensure_demo


@pytest.fixture(scope="module")
def actor(ground_truth: zarr.Group) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Neutral actor vertices (N, 3) m and marker name -> neutral position (3,) m."""
    names = ground_truth.attrs["marker_names"]
    return ground_truth["neutral_vertices"][:], dict(
        zip(names, ground_truth["markers_neutral"][:], strict=True)
    )


@pytest.fixture(scope="module")
def field(actor: tuple[np.ndarray, dict[str, np.ndarray]]) -> CompositeField:
    return face_field(actor[1])


def one(field: CompositeField, name: str, value: float = 1.0) -> np.ndarray:
    """The parameter vector of ``field`` with only ``name`` set."""
    p = np.zeros(len(field.param_names))
    p[field.param_names.index(name)] = value
    return p


def moved(
    field: CompositeField, markers: dict[str, np.ndarray], name: str, which: list[str]
) -> np.ndarray:
    """Displacements (len(which), 3) m of the markers ``which`` under ``name`` at 1."""
    return field.displacement(np.array([markers[w] for w in which]), one(field, name))


def test_fields_are_zero_at_zero_and_smooth_without_inverting(
    ground_truth: zarr.Group, field: CompositeField
) -> None:
    v0, faces = ground_truth["neutral_vertices"][:], ground_truth["faces"][:]
    for comp in field.components:
        assert not comp.displacement(v0, np.zeros(len(comp.param_names))).any()
    assert not field.displacement(v0, np.zeros(len(field.param_names))).any()
    edges = np.unique(np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    length = np.linalg.norm(v0[edges[:, 0]] - v0[edges[:, 1]], axis=1)  # 0.4-6 mm
    sample = v0[::7]
    for name in field.param_names:
        p = one(field, name)
        d = field.displacement(v0, p)
        # no jump: a 1 mm step across an edge (<= 0.6 mm for half of them) would exceed 1.6;
        # the demo's jaw drop stretches the lips more (2.7)
        change = np.linalg.norm(d[edges[:, 0]] - d[edges[:, 1]], axis=1) / length
        assert change.max() < (3.0 if name == "jaw_open" else 1.6), (name, change.max())
        h = 1e-6
        grad = np.stack(
            [
                field.displacement(sample + h * e, p) - field.displacement(sample - h * e, p)
                for e in np.eye(3)
            ],
            axis=2,
        ) / (2 * h)  # (N, 3, 3)
        det = np.linalg.det(np.eye(3) + grad)
        assert det.min() > 0.2, (name, det.min())  # the skin never folds over


def test_composite_sums_the_components(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    v0 = actor[0][::11]
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 1, len(field.param_names))
    total = sum(
        comp.displacement(v0, p[[field.param_names.index(n) for n in comp.param_names]])
        for comp in field.components
    )
    np.testing.assert_allclose(field.displacement(v0, p), total, atol=1e-15)
    smile = field.select(["smile_L"])
    np.testing.assert_array_equal(
        smile.displacement(v0, np.array([0.7])),
        field.components[0].displacement(v0, np.array([0.0, 0.7, 0.0])),
    )
    with pytest.raises(ValueError, match="each must be one of"):
        field.select(["smile_L", "wink"])


def test_brow_raise_lifts_the_brows_and_not_the_chin(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    m = actor[1]
    brow = next(c for c in field.components if isinstance(c, BrowField))
    # the glabella is at the brows' mean height on the midline: the full lift, straight up
    d = moved(field, m, "brow_raise", ["glabella", "brow_in_L", "brow_mid_R", "chin", "ch_L"])
    np.testing.assert_allclose(d[0], [0.0, brow.lift, 0.0], atol=1e-9)
    assert (d[1:3, 1] > 0.8 * brow.lift).all() and not d[1:3, [0, 2]].any()
    assert not d[3:].any()  # below the eyes nothing moves


def test_frown_pulls_the_brows_down_and_together(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    m = actor[1]
    brow = next(c for c in field.components if isinstance(c, BrowField))
    d = moved(field, m, "frown", ["brow_in_L", "brow_in_R", "chin", "ch_R"])
    # each medial brow: its own vector plus the Gaussian tail of the other side's
    gap = np.linalg.norm(m["brow_in_L"] - m["brow_in_R"])
    tail = np.exp(-(gap**2) / (2 * brow.frown_sigma**2))
    mirror = np.array([-1.0, 1.0, 1.0])
    v = np.asarray(brow.frown_vector)
    np.testing.assert_allclose(d[0], v + tail * mirror * v, atol=1e-12)
    np.testing.assert_allclose(d[1], mirror * v + tail * v, atol=1e-12)
    assert d[0, 0] - d[1, 0] < -0.005  # the brows come > 5 mm closer
    np.testing.assert_allclose(d[2:], 0.0, atol=1e-12)


def test_pucker_pushes_the_lips_towards_the_camera_and_draws_them_together(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    v0, m = actor
    mouth = next(c for c in field.components if isinstance(c, MouthField))
    d = field.displacement(v0, one(field, "lip_pucker"))
    # on the plateau of the lip weight: exactly the stated forward motion (+z: the camera)
    plateau = mouth.weight(v0) == 1.0
    assert plateau.sum() > 100
    np.testing.assert_allclose(d[plateau, 2], mouth.forward[0], rtol=1e-12)
    lips = moved(field, m, "lip_pucker", ["cphi_L", "cphi_R", "lip_lower"])
    assert (lips[:, 2] > 0.008).all()
    corners = moved(field, m, "lip_pucker", ["ch_L", "ch_R"])
    assert corners[0, 0] - corners[1, 0] < -0.006  # mouth > 6 mm narrower
    far = moved(field, m, "lip_pucker", ["forehead", "glabella", "ex_L", "pronasale", "chin"])
    assert not far.any()
    # mostly along the view direction
    moving = np.linalg.norm(d, axis=1) > 1e-3
    assert np.abs(d[moving, 2]).mean() > 2 * np.linalg.norm(d[moving, :2], axis=1).mean()


def test_funnel_parts_and_press_closes_the_lips(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    m = actor[1]
    lips = ["cphi_L", "lip_lower"]  # upper lip (philtrum bottom), lower lip
    funnel = moved(field, m, "lip_funnel", lips)
    assert funnel[0, 1] > 0.0015 and funnel[1, 1] < -0.0015 and (funnel[:, 2] > 0.004).all()
    press = moved(field, m, "lip_press", lips)
    assert press[0, 1] < -0.0008 and press[1, 1] > 0.0008 and (press[:, 2] < -0.0015).all()
    assert not moved(field, m, "lip_press", ["forehead", "brow_in_L", "chin"]).any()


def test_sideways_jaw_rotates_the_chin_to_that_side(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    m = actor[1]
    jaw = next(c for c in field.components if isinstance(c, JawSideField))
    chin = m["chin"]
    pivot = np.asarray(jaw.jaw_pivot)
    for name, sign in (("jaw_left", 1.0), ("jaw_right", -1.0)):
        d = moved(field, m, name, ["chin", "forehead", "pronasale", "ex_R"])
        rot = Rotation.from_rotvec([0.0, sign * jaw.max_angle, 0.0]).as_matrix()
        np.testing.assert_allclose(d[0], (chin - pivot) @ rot.T + pivot - chin, atol=1e-12)
        assert sign * d[0, 0] > 0.005  # > 5 mm to the actor's own left / right
        assert not d[1:].any()


def test_cheek_puff_bulges_the_cheeks_outwards_and_forwards(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    m = actor[1]
    puff = next(c for c in field.components if isinstance(c, CheekPuffField))
    d = moved(field, m, "cheek_puff", ["cheek_low_L", "cheek_low_R", "forehead", "brow_in_L"])
    for k, side in ((0, 1.0), (1, -1.0)):
        assert np.linalg.norm(d[k]) > 0.95 * puff.cheek
        assert side * d[k, 0] > 0.003 and d[k, 2] > 0.003 and d[k, 1] == 0.0
    assert np.abs(d[2:]).max() < 1e-6


def test_nose_wrinkle_lifts_the_wings_and_bunches_the_bridge(
    actor: tuple[np.ndarray, dict[str, np.ndarray]], field: CompositeField
) -> None:
    m = actor[1]
    nose = next(c for c in field.components if isinstance(c, NoseWrinkleField))
    d = moved(field, m, "nose_wrinkle", ["al_L", "al_R", "nose_bridge", "chin", "forehead"])
    np.testing.assert_allclose(d[:2, 1], nose.wing_vector[1], rtol=0.05)
    assert d[2, 1] < -0.0015
    assert np.abs(d[3:]).max() < 1e-6


def test_library_is_split_and_every_expression_peaks_once() -> None:
    assert len(LIBRARY) >= 6 and set(TUNING) | set(HELD_OUT) == set(PERFORMANCE_NAMES)
    assert not set(TUNING) & set(HELD_OUT) and DEMO in TUNING
    tuned = {n for name in TUNING if name != DEMO for n in LIBRARY[name].names}
    tuned |= {"jaw_open", "smile_L", "smile_R"}  # the demo's
    held = {n for name in HELD_OUT for n in LIBRARY[name].names}
    assert held <= tuned  # held-out performances recombine tuned expressions
    assert {"brow_raise", "frown", "lip_pucker", "lip_funnel", "cheek_puff"} <= tuned
    for name, spec in LIBRARY.items():
        for n_frames in (24, 90):
            expr = spec.expression(n_frames)
            assert expr.shape == (n_frames, len(spec.names))
            assert np.abs(expr[[0, -1]]).max() < 1e-12, name  # neutral at both ends
            rises = np.diff(np.sign(np.diff(expr, axis=0)), axis=0) < 0
            assert (rises.sum(axis=0) == 1).all(), name  # one maximum per column
            faces = np.zeros((1, 3), dtype=np.int64)
            truth = Truth(np.zeros((n_frames, 3, 3)), faces, expr, list(spec.names))
            peaks = truth.peak_frames()
            keys = {"smile" if n.startswith("smile") else n for n in spec.names}
            assert set(peaks) == keys, name
            for i, n in enumerate(spec.names):
                if not n.startswith("smile"):
                    assert peaks[n] == np.argmax(expr[:, i])


def test_head_motion_comes_from_the_seed_and_the_performance(
    actor: tuple[np.ndarray, dict[str, np.ndarray]],
) -> None:
    markers = actor[1]
    a = performance_setup("lips", markers, 30, 30.0, 1)[1]
    b = performance_setup("lips", markers, 30, 30.0, 1)[1]
    c = performance_setup("lips", markers, 30, 30.0, 2)[1]
    d = performance_setup("brows", markers, 30, 30.0, 1)[1]
    np.testing.assert_array_equal(a.rotvec, b.rotvec)
    assert not np.allclose(a.rotvec, c.rotvec) and not np.allclose(a.rotvec, d.rotvec)
    np.testing.assert_array_equal(a.rotvec[0], 0.0)
    field, demo = performance_setup(DEMO, markers, 30, 30.0, 1)
    assert isinstance(field, AnalyticFaceField)
    np.testing.assert_array_equal(demo.params, demo_performance(30, 30.0, 1).params)


def test_performance_names_are_checked_and_dataset_names_round_trip() -> None:
    with pytest.raises(ValidationError, match="the library has: demo, brows"):
        DemoParams(performance="yawn")
    base = DemoParams(color_noise=2.0)
    assert library_params(DEMO, base) is base
    assert library_params("my-capture", base) is None and library_params("yawn-s0", base) is None
    for name in PERFORMANCE_NAMES:
        for coarse in (False, True):
            for markers in (False, True):
                folder = dataset_name(name, 3, coarse=coarse, markers=markers)
                p = library_params(folder, base)
                assert p is not None and p.color_noise == 2.0
                assert (p.performance, p.seed, p.markers) == (name, 3, markers)
                assert p.n_frames == (24 if coarse else 90)


def test_the_default_demo_is_the_demo_field_and_performance(ground_truth: zarr.Group) -> None:
    """The demo dataset (performance 'demo', seed 0) is what the demo's own code path gives:
    AnalyticFaceField from the mouth-corner markers driven by demo_performance."""
    names = ground_truth.attrs["marker_names"]
    m0 = ground_truth["markers_neutral"][:]
    v0 = ground_truth["neutral_vertices"][:]
    field = AnalyticFaceField(
        ch_left=tuple(m0[names.index("ch_L")]), ch_right=tuple(m0[names.index("ch_R")])
    )
    n = ground_truth["expression"].shape[0]
    perf = demo_performance(n, 30.0, 0)
    np.testing.assert_array_equal(ground_truth["expression"][:], perf.params)
    np.testing.assert_array_equal(ground_truth["head_pose"][:], perf.head_pose())
    expected = np.stack([v0 + field.displacement(v0, e) for e in perf.params]).astype(np.float32)
    np.testing.assert_array_equal(ground_truth["vertices_actor"][:], expected)
    attrs = ground_truth.attrs
    assert attrs["expression_model"] == "AnalyticFaceField" and attrs["performance"] == DEMO
    assert attrs["expression_field"] == field.to_dict()
    assert attrs["expression_names"] == ["jaw_open", "smile_L", "smile_R"]


def marker_pixels(color: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Mask (H, W) of marker-coloured pixels (bluer than red by 20 levels: skin is redder,
    the background is only ~5 levels bluer) on the face (valid true depth, 2 px inside)."""
    face = cv2.erode(np.isfinite(depth).astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    rgb = color.astype(np.int16)
    return face & (rgb[..., 2] - rgb[..., 0] > 20)


def test_markerless_render_has_no_dots_and_differs_only_at_them(
    demo_dir: Path, ground_truth: zarr.Group, tmp_path: Path
) -> None:
    bare = generate_demo(tmp_path / "bare", params=DemoParams(n_frames=2, markers=False), workers=1)
    read = lambda d: cv2.imread(str(d / "rgbd/color/000000.png"))[..., ::-1]  # noqa: E731
    dotted, plain = read(demo_dir), read(bare)
    depth = ground_truth["depth_true"][0]
    uv = project(ground_truth["markers_camera"][0].astype(np.float64), ground_truth["K"][:])

    def to_dots(mask: np.ndarray) -> np.ndarray:
        """Distance (M, K) px of each pixel of ``mask`` to each marker's projection."""
        rows, cols = np.nonzero(mask)
        return np.linalg.norm(np.stack([cols, rows], axis=1)[:, None] - uv[None], axis=2)

    found = to_dots(marker_pixels(dotted, depth))
    assert found.min(axis=1).max() < 3.0  # every marker-coloured pixel is at a marker
    assert (found.min(axis=0) < 3.0).sum() >= 30  # most of the 36 dots are seen
    assert not marker_pixels(plain, depth).any()
    # the same frame otherwise (texture, shading, noise): only pixels at the dots differ
    differ = to_dots((dotted != plain).any(axis=2))
    assert len(differ) > 0 and differ.min(axis=1).max() < 4.0
    depth_png = lambda d: (d / "rgbd/depth/000000.png").read_bytes()  # noqa: E731
    assert depth_png(demo_dir) == depth_png(bare)


def test_a_coarse_library_dataset_holds_its_performance(tmp_path: Path) -> None:
    params = library_params("emotions-s1-coarse", DemoParams())
    assert params is not None
    spec = LIBRARY["emotions"]
    params = params.model_copy(update={"n_frames": 13})  # peaks at frames 2, 6, 10
    out = generate_demo(tmp_path / "emotions", params=params, workers=1)
    gt = zarr.open_group(out / "ground_truth.zarr", mode="r")
    assert (
        gt.attrs["performance"] == "emotions" and gt.attrs["expression_model"] == "CompositeField"
    )
    assert gt.attrs["expression_names"] == list(spec.names)
    np.testing.assert_array_equal(gt["expression"][:], spec.expression(13))
    names = gt.attrs["marker_names"]
    m0 = gt["markers_neutral"][:]
    field = face_field(dict(zip(names, m0, strict=True))).select(spec.names)
    v0, verts = gt["neutral_vertices"][:], gt["vertices_actor"][:]
    for t in (0, 2, 7):
        expected = (v0 + field.displacement(v0, gt["expression"][t])).astype(np.float32)
        np.testing.assert_array_equal(verts[t], expected)
    peaks = load_truth(out / "ground_truth.zarr", 13).peak_frames()
    assert truth_peaks(out / "ground_truth.zarr", 13) == peaks  # what render reads
    assert truth_peaks(out / "no_truth.zarr", 13) == {}
    assert set(peaks) == {"brow_raise", "jaw_open", "frown", "lip_press", "nose_wrinkle", "smile"}
    assert peaks["brow_raise"] == peaks["jaw_open"] < peaks["frown"] == peaks["lip_press"]
    assert peaks["lip_press"] < peaks["nose_wrinkle"] == peaks["smile"]
    lift = gt["markers_actor"][:] - m0  # (T, K, 3) m
    k = {n: names.index(n) for n in ("brow_in_L", "al_L", "chin")}
    assert lift[peaks["brow_raise"], k["brow_in_L"], 1] > 0.003
    assert lift[peaks["brow_raise"], k["chin"], 1] < -0.002  # the jaw opens with it
    assert lift[peaks["frown"], k["brow_in_L"], 1] < -0.002
    assert lift[peaks["nose_wrinkle"], k["al_L"], 1] > 0.0015
    np.testing.assert_allclose(lift[[0, -1]], 0.0, atol=1e-6)


def test_only_demo_and_library_names_are_generated_on_demand(
    demo_dir: Path, tmp_path: Path
) -> None:
    config = create_model("Config", __base__=PipelineConfig, demo=(DemoParams, DemoParams()))

    def at(name: str) -> PipelineConfig:
        return config(dataset=DatasetParams(name=name, dir=str(tmp_path / name)))

    assert ensure_demo(at("my-capture")) is None  # not a library name: ingest reports it
    assert not (tmp_path / "my-capture").exists()
    recorded = tmp_path / "lips-s2-coarse"
    recorded.mkdir()
    (recorded / "capture.bag").symlink_to(demo_dir / "capture.bag")
    assert ensure_demo(at("lips-s2-coarse")) is None  # a recording is there: kept
    assert sorted(p.name for p in recorded.iterdir()) == ["capture.bag"]

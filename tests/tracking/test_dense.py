"""Dense capture recovers a known smooth warp of a real face photo (scikit-image's astronaut).

The photo is laid on a gently curved surface 0.5 m in front of a pinhole camera; over 30 frames
the surface moves by a known smooth field (up to 10 px sideways and 3 mm towards the camera),
and the colour and depth frames are made by warping the photo and the depth with it. Dense
capture of a grid mesh on the surface must recover every vertex's motion.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.typing import NDArray

from physanim.tracking.dense import (
    _enlarge,
    _flow_engine,
    _reduce,
    dense_track,
    dis_flow,
    flow_image,
    flow_window,
    smooth_depth,
)
from physanim.tracking.dense_params import DEPTH_CHANGE_SIGMA_PX, DenseParams
from physanim.tracking.lift import backproject

skimage_data = pytest.importorskip("skimage.data")

SIZE, T, F_PX = 256, 30, 500.0
FPS = 30.0  # frame rate of the warped recordings, 1/s
K = np.array([[F_PX, 0.0, SIZE / 2], [0.0, F_PX, SIZE / 2], [0.0, 0.0, 1.0]])


def warp(uv: NDArray, t: int) -> tuple[NDArray, NDArray]:
    """The true motion at frame t of surface points at neutral pixels ``uv`` (P, 2): pixel
    shift (P, 2) px and depth change (P,) m (a smooth bump that grows and decays)."""
    a = np.sin(np.pi * t / (T - 1)) ** 2
    c = (uv - SIZE / 2) / SIZE
    bump = np.exp(-(c**2).sum(axis=1) / 0.15)
    shift = a * np.stack([10.0 * bump * np.cos(3 * c[:, 1]), -7.0 * bump + 3.0 * c[:, 0]], 1)
    return shift, a * 0.003 * bump


def neutral_depth(uv: NDArray) -> NDArray:
    c = (uv - SIZE / 2) / SIZE
    return 0.5 - 0.02 * np.exp(-(c**2).sum(axis=1) / 0.1)


def render(photo: NDArray, t: int) -> tuple[NDArray, NDArray]:
    """Colour (H, W, 3) and depth (H, W) m of frame t: the neutral pixel p0 of each output
    pixel p solves p0 + shift(p0) = p (fixed-point iterations on the smooth field)."""
    ys, xs = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    p = np.stack([xs.ravel(), ys.ravel()], 1)
    p0 = p.copy()
    for _ in range(8):
        p0 = p - warp(p0, t)[0]
    dz = warp(p0, t)[1]
    maps = p0.reshape(SIZE, SIZE, 2).astype(np.float32)
    color = cv2.remap(photo, maps[..., 0], maps[..., 1], cv2.INTER_CUBIC)
    depth = (neutral_depth(p0) + dz).reshape(SIZE, SIZE)
    return color, depth.astype(np.float32)


@pytest.fixture(scope="module")
def recording() -> tuple[NDArray, NDArray, NDArray, NDArray]:
    photo = skimage_data.astronaut()[20:276, 130:386]  # the face
    frames = [render(photo, t) for t in range(T)]
    color = np.stack([f[0] for f in frames])
    depth = np.stack([f[1] for f in frames])
    # the grid mesh: every 4th pixel of the central 200 x 200 px, lifted at frame 0
    g = np.arange(28, 228, 4, dtype=np.float64)
    gx, gy = np.meshgrid(g, g)
    uv0 = np.stack([gx.ravel(), gy.ravel()], 1)
    n = len(g)
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    # triangles oriented towards the camera (-z), as a scan's are
    faces = np.concatenate([quads[:, [0, 2, 1]], quads[:, [0, 3, 2]]])
    return color, depth, uv0, faces


def test_dense_capture_recovers_a_known_warp_of_a_real_photo(recording):
    color, depth, uv0, faces = recording
    vertices = backproject(uv0, neutral_depth(uv0), K)
    # the pose is known: no registration (a bump on a plane would let ICP turn about the axis)
    params = DenseParams(
        refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0, smoothing_m=0.001
    )
    pose = np.tile(np.eye(4), (T, 1, 1))
    dense = dense_track(color, depth, K, pose, vertices, faces, params, fps=FPS)
    assert dense.seen.all()
    px_err, mm_err = [], []
    for t in range(T):
        shift, dz = warp(uv0, t)
        true = backproject(uv0 + shift, neutral_depth(uv0) + dz, K)
        got = vertices + dense.displacement[t]
        proj = got @ K.T
        px_err.append(np.linalg.norm(proj[:, :2] / proj[:, 2:] - (uv0 + shift), axis=1))
        mm_err.append(np.linalg.norm(got - true, axis=1) * 1e3)
    px, mm = np.median(px_err), np.median(mm_err)
    print(f"median error {px:.3f} px, {mm:.3f} mm over {T} frames")
    assert px <= 1.0  # the acceptance; measured about 0.1 px
    assert mm <= 0.5
    # the motion is recovered, not just small: at the peak the median true shift is > 3 px
    assert np.median(np.linalg.norm(warp(uv0, T // 2)[0], axis=1)) > 3.0


def test_unobserved_vertices_are_marked_and_filled_from_neighbours(recording):
    """A hole in one frame's depth: its vertices get confidence 0, and the fill (the field is
    smooth) still puts them within 1 mm of the truth (the motion there is ~10 mm)."""
    color, depth, uv0, faces = recording
    depth = depth.copy()
    t = T // 2
    depth[t, 100:140, 100:140] = np.nan
    vertices = backproject(uv0, neutral_depth(uv0), K)
    params = DenseParams(
        refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0, prior="none"
    )
    pose = np.tile(np.eye(4), (T, 1, 1))
    dense = dense_track(color, depth, K, pose, vertices, faces, params, fps=FPS)
    shift, dz = warp(uv0, t)
    at = uv0 + shift  # where the vertices are in frame t
    hole = ((at > 104) & (at < 136)).all(axis=1)
    around = ((at > 96) & (at < 144)).all(axis=1)
    assert hole.sum() > 20
    assert not dense.confidence[t, hole].any()
    assert dense.confidence[t, ~around].mean() > 0.9
    true = backproject(uv0 + shift, neutral_depth(uv0) + dz, K)
    err = np.linalg.norm(vertices + dense.displacement[t] - true, axis=1)
    # a harmonic fill flattens the bump across the 30 mm hole: measured 0.56 mm of ~10 mm
    assert np.median(err[hole]) < 1e-3


def test_each_frames_flow_starts_from_the_frame_befores_in_its_direction(recording, monkeypatch):
    """Frame t's flow from the neutral frame (and back) starts from frame t - 1's in the same
    direction, so a large motion is reached in steps (the held-out vowels rendered without
    markers: 0.222 -> 0.199 at the jaw drop, benchmarks/bench_dense.py), and the starts do
    not change a motion that DIS finds from rest (this warp: within 0.05 px, the median)."""
    import physanim.tracking.dense as dense_module

    color, depth, uv0, faces = recording
    engine = dense_module._flow_engine
    engines: list[Recorded] = []

    class Recorded:
        """A DIS engine that keeps each call's start and result; ``cold``: ignore starts."""

        def __init__(self, dis: cv2.DISOpticalFlow, cold: bool) -> None:
            self.dis, self.cold = dis, cold
            self.calls: list[tuple[NDArray | None, NDArray]] = []
            engines.append(self)

        def calc(self, a: NDArray, b: NDArray, start: NDArray | None) -> NDArray:
            given = None if start is None else start.copy()
            out = self.dis.calc(a, b, None if self.cold else start)
            self.calls.append((given, out.copy()))
            return out

    vertices = backproject(uv0, neutral_depth(uv0), K)
    # one pass per call (the passes after the first start from the warped frame, not from
    # frame t - 1: test_a_second_flow_pass_reads_what_the_first_leaves)
    params = DenseParams(
        refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0, flow_passes=1
    )
    pose = np.tile(np.eye(4), (T, 1, 1))
    runs = {}
    for cold in (False, True):
        monkeypatch.setattr(dense_module, "_flow_engine", lambda p, c=cold: Recorded(engine(p), c))
        runs[cold] = dense_track(color, depth, K, pose, vertices, faces, params, fps=FPS)
    forward, backward = engines[:2]  # the warm run's engines
    for calls in (forward.calls, backward.calls):
        assert len(calls) == T and calls[0][0] is None
        for (_, before), (start, _) in zip(calls, calls[1:], strict=False):
            np.testing.assert_array_equal(start, before)
    apart = [
        np.linalg.norm(_pixels(vertices + runs[False].displacement[t])
                       - _pixels(vertices + runs[True].displacement[t]), axis=1)
        for t in range(T)
    ]  # fmt: skip
    assert np.median(apart) < 0.05


def test_a_second_flow_pass_reads_what_the_first_leaves():
    """On faint texture (blurred noise of 5 grey levels, as skin's pores and mottling) a
    bump of motion 6 px wide and 2 px high (a lip press at the demo camera's scale) is read
    short by one DIS pass; the second pass, from the target warped back by the first's flow,
    reads most of what is left. Mean over 4 textures of the share of the motion not read
    (1 - the flow's component along the true motion over the true motion's, where the bump
    is above a fifth of its height): measured 0.035 with one pass, 0.017 with two."""
    params = DenseParams()
    n, sigma, height = 160, 6.0, 2.0
    ys, xs = np.mgrid[0:n, 0:n].astype(np.float32)
    bump = np.exp(-((xs - n / 2) ** 2 + (ys - n / 2) ** 2) / (2 * sigma**2))
    motion = np.stack([0.3 * height * bump, height * bump], -1).astype(np.float32)
    # the target's pixel x shows the source's pixel x0 with x0 + motion(x0) = x
    x0, y0 = xs.copy(), ys.copy()
    for _ in range(10):
        at = cv2.remap(motion, x0, y0, cv2.INTER_LINEAR)
        x0, y0 = xs - at[..., 0], ys - at[..., 1]
    moving = bump > 0.2
    short = {1: [], 2: []}
    for seed in range(4):
        noise = cv2.GaussianBlur(
            np.random.default_rng(seed).normal(size=(n, n)).astype(np.float32), (0, 0), 1.2
        )
        texture = 128.0 + 5.0 * noise / noise.std()
        source = texture.astype(np.uint8)
        target = np.clip(cv2.remap(texture, x0, y0, cv2.INTER_CUBIC), 0, 255).astype(np.uint8)
        a, b = (_enlarge(flow_image(g, params.flow_normalise_px), params) for g in (source, target))
        for passes in short:
            flow = _reduce(dis_flow(_flow_engine(params), a, b, None, passes, 3.0), (n, n), params)
            along = (flow[moving] * motion[moving]).sum() / (motion[moving] ** 2).sum()
            short[passes].append(1.0 - along)
    one, two = np.mean(short[1]), np.mean(short[2])
    print(f"share of the motion not read: one pass {one:.3f}, two passes {two:.3f}")
    assert one > 0.02  # the shortfall exists
    assert abs(two) < 0.6 * one


def _pixels(points: NDArray) -> NDArray:
    """Pixels (P, 2) of camera-frame points (P, 3) m."""
    proj = points @ K.T
    return proj[:, :2] / proj[:, 2:]


def test_smooth_depth_ignores_invalid_pixels():
    depth = np.full((20, 20), 0.5, np.float32)
    depth[5:8, 5:8] = np.nan
    depth[12, 12] = 0.0
    out = smooth_depth(depth, 1.5)
    assert np.allclose(out[np.isfinite(out)], 0.5, atol=1e-6)
    assert np.isfinite(out[12, 12]) and np.isfinite(out[6, 6])  # filled from valid neighbours


def test_the_flow_window_holds_the_points_under_every_pose_and_stays_in_the_image():
    """Two points 2 cm apart at 0.5 m, the head shifted 1 cm right in the second frame: the
    window spans both frames' pixels plus the margin; a margin past the border is clipped."""
    points = np.array([[-0.01, 0.0, 0.0], [0.01, 0.0, 0.0]])
    poses = np.tile(np.eye(4), (2, 1, 1))
    poses[:, 2, 3] = 0.5
    poses[1, 0, 3] = 0.01
    x0, y0, x1, y1 = flow_window(points, poses, K, (SIZE, SIZE), 4)
    # pixels: x = 128 + 500 * x / 0.5 -> 118, 138 (frame 0) and 128, 148 (frame 1)
    assert (x0, x1) == (118 - 4, 148 + 4 + 1) and (y0, y1) == (128 - 4, 128 + 4 + 1)
    assert flow_window(points, poses, K, (SIZE, SIZE), 200) == (0, 0, SIZE, SIZE)


def test_the_frames_unfold_what_the_prior_folds_and_fill_what_they_do_not_see():
    """A 30 x 30 mm grid (1 mm) whose true motion is a smooth 2 mm bump towards the camera;
    the prior (the kinematic scan) has it plus a fold (every other row 1.5 mm up, past the
    next: half the triangles turned over), and every vertex but a 5 x 5 patch is observed
    exactly. The fill follows the observations: off the patch no triangle is turned and the
    error is 0.024 mm median, 0.11 max (the 1 mm smoothing of the bump; smoothing the
    departure from the prior kept the fold: 801 turned, 0.67 mm); the unseen patch follows
    the prior and its neighbours' correction, within the fold's 1.5 mm, except where that
    keeps the prior's fold: there it follows its neighbours alone, and no triangle at all is
    turned."""
    from physanim.evaluate.surfaces import RestTriangles
    from physanim.tracking.dense import DenseObservations, fill_motion

    n = 31
    vertices, faces = _grid(n)
    idx = np.arange(n * n).reshape(n, n)
    centre = (vertices[:, :2] - 0.015) / 0.008
    true = np.zeros((2, n * n, 3))
    true[1, :, 2] = -0.002 * np.exp(-(centre**2).sum(axis=1))
    prior = true.copy()
    prior[1, (idx % 2 == 1).T.ravel(), 1] += 0.0015  # odd rows up past the next: a fold
    unseen = (np.abs(vertices[:, :2] - 0.015) <= 0.0021).all(axis=1)
    seen = ~unseen
    obs = DenseObservations(
        seen, true[:, seen], np.zeros((2, int(seen.sum()))), np.tile(np.eye(4), (2, 1, 1)), 0.0
    )
    params = DenseParams(temporal_sigma_s=0.0, smoothing_m=0.001)
    displacement, confidence, unfolded = fill_motion(obs, vertices, faces, params, prior, fps=FPS)
    np.testing.assert_array_equal(confidence[1], seen)
    ring = (np.abs(vertices[:, :2] - 0.015) <= 0.0041).all(axis=1)
    err = np.linalg.norm(displacement[1] - true[1], axis=1)
    assert np.median(err[~ring]) < 5e-5 and err[~ring].max() < 1.5e-4
    assert err[unseen].max() < 1.5e-3
    rest = RestTriangles.of(vertices, faces[~ring[faces].any(axis=1)])
    assert RestTriangles.of(vertices, faces).stretch(vertices + prior[1])[1].mean() > 0.45
    assert not rest.stretch(vertices + displacement[1])[1].any()
    whole = RestTriangles.of(vertices, faces).stretch(vertices + displacement[1])[1]
    assert not whole.any() and 0 < unfolded <= unseen.sum()


def _grid(n: int) -> tuple[NDArray, NDArray]:
    """An n x n grid of 1 mm spacing in the z = 0 plane: vertices (n^2, 3) m, faces."""
    g = np.arange(n) * 1e-3
    gx, gy = np.meshgrid(g, g)
    vertices = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n)], 1)
    idx = np.arange(n * n).reshape(n, n)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    return vertices, np.concatenate([quads[:, [0, 2, 1]], quads[:, [0, 3, 2]]])


def _smooth_noise(rng: np.random.Generator, points: NDArray, rms: NDArray) -> NDArray:
    """A smooth random field (P, 3) m at ``points`` (P, 3) m: per coordinate, a sum of 8 plane
    waves 5-15 mm long in random directions and phases, of RMS ``rms`` (3,) m (a depth
    camera's error after the depth change's local fit: correlated over a few mm)."""
    out = np.zeros((len(points), 3))
    for c in range(3):
        angle = rng.uniform(0, 2 * np.pi, 8)
        k = 2 * np.pi / rng.uniform(0.005, 0.015, 8)
        phase = rng.uniform(0, 2 * np.pi, 8)
        waves = np.cos(
            points[:, :1] * (k * np.cos(angle)) + points[:, 1:2] * (k * np.sin(angle)) + phase
        )
        out[:, c] = waves.sum(axis=1) * rms[c] / 2.0  # 8 unit waves: RMS 2
    return out


def test_the_neutral_frames_error_is_taken_out_where_the_skin_rests():
    """Each frame t of a 40 x 40 mm grid is observed with a smooth error e_t (0.1 mm RMS,
    mostly in depth), against the neutral frame, which has its own: the motion observed is
    the true one plus e_t - e_0, and e_0 is shared by every frame. A bump rises 2 mm and
    falls back over frames 10-25 of 60; one corner moves 1 mm from frame 1 on and never
    rests. The shared error is recovered to its expected spread over about 45 rest frames
    (0.1 / sqrt(45) = 0.015 mm) wherever the skin rests in some frames (the bump too,
    outside its motion), the corner gets none (its motion is kept, not taken for error), and
    the filled motion's error at the bump's peak falls to half."""
    from physanim.tracking.dense import (
        DenseObservations,
        fill_motion,
        neutral_error,
        without_neutral_error,
    )

    n, T = 41, 60
    vertices, faces = _grid(n)
    rng = np.random.default_rng(3)
    rms = np.array([0.03, 0.03, 0.09]) * 1e-3
    errors_t = np.stack([_smooth_noise(rng, vertices, rms) for _ in range(T)])
    ramp = np.clip(np.sin(np.pi * (np.arange(T) - 10) / 15), 0, None) * (np.arange(T) <= 25)
    bump = np.exp(-(((vertices[:, :2] - 0.02) / 0.008) ** 2).sum(axis=1))
    true = np.zeros((T, n * n, 3))
    true[:, :, 2] = -0.002 * ramp[:, None] * bump[None]
    corner = (vertices[:, :2] > 0.032).all(axis=1)
    true[1:, corner, 0] = 0.001
    observed = true + errors_t - errors_t[0]
    seen = np.ones(n * n, dtype=bool)
    poses = np.tile(np.eye(4), (T, 1, 1))
    obs = DenseObservations(seen, observed, np.zeros((T, n * n)), poses, 0.0)
    params, edge = DenseParams(), 1e-3
    found, resting = neutral_error(obs, faces, params, edge, FPS)
    rests = ~(vertices[:, :2] > 0.029).all(axis=1)  # 3 mm from the corner's motion
    err = np.linalg.norm(found[rests] + errors_t[0, rests], axis=1)
    assert np.sqrt((err**2).mean()) < 2.5e-5  # measured 0.016 mm
    assert not found[corner].any() and not resting[corner].any()
    assert (resting[rests] >= 20).all()  # the bump's vertices rest in about 40 of 59 frames
    off = params.model_copy(update={"rest_factor": 0.0})
    assert not neutral_error(obs, faces, off, edge, FPS)[0].any()
    peak = int(np.argmax(ramp))
    errors = []
    for p in (off, params):
        taken, neutral = without_neutral_error(obs, vertices, faces, p, fps=FPS)
        fitted, _, _ = fill_motion(taken, vertices, faces, p, fps=FPS)
        e = np.linalg.norm(fitted[peak, rests] - true[peak, rests], axis=1)
        errors.append(np.sqrt((e**2).mean()))
    assert errors[1] < 0.5 * errors[0], errors  # measured 0.097 -> 0.040 mm
    # all but the corner and the skin within the smoothing's reach of it
    assert rests.mean() - 0.01 <= neutral.resting_fraction < 1.0 - corner.mean()
    assert neutral.rms_m == pytest.approx(np.sqrt((errors_t[0] ** 2).sum(axis=1).mean()), rel=0.2)
    # from frame 6: the fit over time rounds the corner's step at frame 1
    kept = fitted[6:, corner & (vertices[:, :2] > 0.036).all(axis=1), 0]
    assert np.allclose(kept, 0.001, atol=1e-4)


def test_a_head_pose_tilted_by_an_expression_is_corrected_by_the_resting_skin():
    """An 80 x 80 mm grid (2 mm spacing) is observed for 60 frames with 0.05 mm of noise per
    vertex and frame; a bump rises 2 mm and falls back over frames 10-25, and the head pose
    of those frames is off by a rotation that grows with it to 0.1 degrees about an axis
    through the grid's corner, with 0.03 mm of translation (an expression tilting the pose,
    as at the demo's smile). The rotation's angle is recovered per frame to 0.02 degrees,
    the pose's error in the motion at the bump's peak falls to a fifth, on the resting skin
    and on the bump, and the frames without the error are left within the noise. The skin
    far from the axis moves more than the rest threshold there: only the passes that look
    for rest again in the corrected motion find the whole angle (one pass: 0.05 of 0.1).
    Where only a strip 8 mm wide rests, which fixes a rotation poorly, the pose is left
    alone."""
    from scipy.spatial.transform import Rotation

    from physanim.tracking.dense import DenseObservations, rest_pose

    n, T = 41, 60
    vertices, faces = _grid(n)
    vertices *= 2.0
    rng = np.random.default_rng(5)
    ramp = np.clip(np.sin(np.pi * (np.arange(T) - 10) / 15), 0, None) * (np.arange(T) <= 25)
    bump = np.exp(-(((vertices[:, :2] - 0.04) / 0.008) ** 2).sum(axis=1))
    true = np.zeros((T, n * n, 3))
    true[:, :, 2] = -0.002 * ramp[:, None] * bump[None]
    axis = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    observed = np.empty_like(true)
    poses = np.tile(np.eye(4), (T, 1, 1))
    for t in range(T):
        rot = Rotation.from_rotvec(np.radians(0.1 * ramp[t]) * axis).as_matrix()
        shift = np.array([0.02, -0.02, 0.01]) * 1e-3 * ramp[t]
        observed[t] = (vertices + true[t]) @ rot.T + shift - vertices
    noise = rng.normal(0.0, 0.05e-3, observed.shape)
    noise[0] = 0.0
    observed += noise
    obs = DenseObservations(np.ones(n * n, bool), observed, np.zeros((T, n * n)), poses, 0.0)
    corrected, angles = rest_pose(obs, vertices, faces, DenseParams(), fps=FPS)
    assert np.abs(angles - 0.1 * ramp).max() < 0.02, angles.round(3)  # measured 0.009
    peak = int(np.argmax(ramp))
    rests = bump < 0.01

    def rms(u: NDArray, mask: NDArray) -> float:
        """RMS error (m) at ``mask`` of the peak's motion ``u`` beside the noise added."""
        e = u - true[peak] - noise[peak]
        return float(np.sqrt(((e**2).sum(axis=1))[mask].mean()))

    before, after = rms(observed[peak], rests), rms(corrected.displacement[peak], rests)
    assert after < before / 5.0, (before, after)  # measured 0.050 -> 0.003 mm
    moving = bump > 0.5
    assert rms(corrected.displacement[peak], moving) < before / 5.0  # measured 0.001 mm
    still = ramp == 0
    assert np.allclose(corrected.displacement[still], observed[still], atol=2e-5)
    # the corrected pose carries the corrected points where the observed pose took them
    t = peak
    cam_before = (vertices + observed[t]) @ poses[t][:3, :3].T + poses[t][:3, 3]
    pose = corrected.head_pose[t]
    cam_after = (vertices + corrected.displacement[t]) @ pose[:3, :3].T + pose[:3, 3]
    np.testing.assert_allclose(cam_after, cam_before, atol=1e-12)
    off = DenseParams(pose_rest_factor=0.0)
    assert rest_pose(obs, vertices, faces, off, fps=FPS)[0] is obs
    # where only a strip of the grid rests (its inner part, 8 mm wide), the pose is left alone
    strip = vertices[:, 0] < 0.017
    narrow = observed.copy()
    narrow[30:50, ~strip, 2] += 0.001
    obs = DenseObservations(np.ones(n * n, bool), narrow, np.zeros((T, n * n)), poses, 0.0)
    _, angles = rest_pose(obs, vertices, faces, DenseParams(), fps=FPS)
    assert not angles[33:47].any() and angles[:26].any()


def test_the_flow_follows_the_skin_where_its_shading_changes(recording):
    """The light falls on a turning surface more or less brightly: each frame's colour is
    scaled by a smooth gain that grows over the bump (to 1.4 times at the peak, darker on its
    far side). Matching local contrast (``flow_normalise_px``) recovers the warp where
    matching brightness is misled; shown at the camera's pixels with OpenCV's weight of
    brightness constancy (5), where the default flow (enlarged images, weight 0.5) is less
    misled by the light to begin with, and follows it as closely."""
    color, depth, uv0, faces = recording
    ys, xs = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    c = np.stack([xs, ys], -1) / SIZE - 0.5
    lit = []
    for t in range(T):
        a = np.sin(np.pi * t / (T - 1)) ** 2
        gain = 1.0 + 0.4 * a * np.exp(-(c**2).sum(-1) / 0.05) * (0.5 + c[..., 0] * 2.0)
        lit.append(np.clip(color[t] * gain[..., None], 0, 255).astype(np.uint8))
    lit = np.stack(lit)
    vertices = backproject(uv0, neutral_depth(uv0), K)
    pose = np.tile(np.eye(4), (T, 1, 1))
    camera_pixels = dict(
        flow_upsample=1, flow_patch_px=4, flow_stride_px=1, flow_constancy_weight=5.0
    )
    errors = {}
    for name, flow in (
        ("brightness", dict(camera_pixels, flow_normalise_px=0.0)),
        ("contrast", dict(camera_pixels, flow_normalise_px=4.0)),
        ("default", {}),
    ):
        params = DenseParams(
            refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0,
            smoothing_m=0.001, **flow,
        )  # fmt: skip
        dense = dense_track(lit, depth, K, pose, vertices, faces, params, fps=FPS)
        px = []
        for t in range(T):
            moved = _pixels(vertices + dense.displacement[t])
            px.append(np.linalg.norm(moved - (uv0 + warp(uv0, t)[0]), axis=1))
        errors[name] = float(np.percentile(px, 90))
    print("90th percentile pixel error:", errors)
    assert errors["contrast"] <= 0.5
    assert errors["contrast"] < 0.8 * errors["brightness"]  # measured 0.12 against 0.19 px
    assert errors["default"] < 0.9 * errors["brightness"]  # measured 0.15 px


def test_the_flow_on_enlarged_images_reports_camera_pixels(recording):
    """With ``flow_upsample`` the flow runs on images enlarged 2 or 3 times and its field is
    averaged back to the camera's pixels: the warp is recovered as closely as at the camera's
    pixels (a field left in enlarged pixels would double or triple every motion)."""
    color, depth, uv0, faces = recording
    vertices = backproject(uv0, neutral_depth(uv0), K)
    pose = np.tile(np.eye(4), (T, 1, 1))
    medians = {}
    for upsample, patch, stride in ((1, 4, 1), (2, 6, 3), (3, 8, 4)):
        params = DenseParams(
            refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0,
            smoothing_m=0.001, flow_upsample=upsample, flow_patch_px=patch,
            flow_stride_px=stride,
        )  # fmt: skip
        dense = dense_track(color, depth, K, pose, vertices, faces, params, fps=FPS)
        px = [
            np.linalg.norm(_pixels(vertices + dense.displacement[t]) - (uv0 + warp(uv0, t)[0]),
                           axis=1)
            for t in range(T)
        ]  # fmt: skip
        medians[upsample] = float(np.median(px))
    print("median pixel error by enlargement:", medians)
    # the true motion reaches 10 px; measured about 0.1 px at each enlargement
    assert max(medians.values()) < 0.2


def test_the_depth_change_keeps_the_peak_of_a_narrow_bump(recording):
    """Lips pushed towards the camera (a pucker) are a narrow bump of the depth change. Its
    Gaussian-weighted mean is flattened at the peak (by about sigma^2 / 2 times its
    curvature); the local quadratic (``depth_change_degree`` 2) keeps the peak."""
    color, _, uv0, faces = recording
    still = np.repeat(color[:1], T, axis=0)  # the texture stays; only the depth changes
    ys, xs = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    pix = np.stack([xs.ravel(), ys.ravel()], 1)
    width_px, height_m = 8.0, 0.004

    def bump(uv: NDArray, t: int) -> NDArray:
        a = np.sin(np.pi * t / (T - 1)) ** 2
        return -a * height_m * np.exp(-((uv - SIZE / 2) ** 2).sum(axis=1) / (2 * width_px**2))

    depth = np.stack([(neutral_depth(pix) + bump(pix, t)).reshape(SIZE, SIZE) for t in range(T)])
    vertices = backproject(uv0, neutral_depth(uv0), K)
    pose = np.tile(np.eye(4), (T, 1, 1))
    peak = np.linalg.norm(uv0 - SIZE / 2, axis=1) < 2.0
    t = T // 2
    errors = {}
    for degree in (0, 2):
        params = DenseParams(
            refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0,
            smoothing_m=0.0, depth_change_degree=degree,
        )  # fmt: skip
        dense = dense_track(
            still, depth.astype(np.float32), K, pose, vertices, faces, params, fps=FPS
        )  # fmt: skip
        true = backproject(uv0, neutral_depth(uv0) + bump(uv0, t), K)
        got = vertices + dense.displacement[t]
        errors[degree] = float(np.abs(got[peak, 2] - true[peak, 2]).max())
    print(f"depth error at the bump's peak (4 mm): mean {errors[0] * 1e3:.2f} mm, "
          f"quadratic {errors[2] * 1e3:.2f} mm")  # fmt: skip
    assert errors[0] > 0.5e-3  # the mean flattens the peak: about 1 mm of 4
    assert errors[2] < 0.35 * errors[0]  # measured 0.21 mm: the bump's fourth-order part


def test_a_stereo_pairs_right_flow_reads_the_change_of_depth_the_matched_depth_blurs(recording):
    """From a stereo pair the change of depth is also read from the disparity change of the
    left and right images' flows (``stereo_flow_weight``). The right images of the warped
    photo are rendered through a rectified pair (baseline 60 mm, principal points offset so
    the surface's mean depth has no disparity); the "matched" depth is the true depth plus
    0.5 mm of noise correlated over 6 px, new in every frame, as a matcher's error. The
    flows follow the same texture in both images, so their depth change is free of that
    noise: the median depth error of the motion falls as the weight grows (measured 0.28,
    0.21 and 0.14 mm at weights 0, 1/3 and 1)."""
    from physanim.capture.frames import StereoRight

    color, depth, uv0, faces = recording
    fx_baseline = F_PX * 0.06
    doffs = fx_baseline / 0.5
    ys, xs = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)
    right = np.empty_like(color)
    for t in range(T):
        # the right pixel q shows the left pixel p with p - (fx B / z(p) - doffs) = q
        p = xs.copy()
        for _ in range(6):
            z = cv2.remap(depth[t], p, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            p = xs + (fx_baseline / z - doffs)
        right[t] = cv2.remap(color[t], p, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    rng = np.random.default_rng(0)
    matched = depth.copy()
    for t in range(T):
        noise = cv2.GaussianBlur(rng.normal(size=(SIZE, SIZE)).astype(np.float32), (0, 0), 6.0)
        matched[t] += 0.0005 * noise / noise.std()
    vertices = backproject(uv0, neutral_depth(uv0), K)
    pose = np.tile(np.eye(4), (T, 1, 1))
    pair = StereoRight(right, fx_baseline, doffs)
    errors = {}
    for weight in (0.0, 1 / 3, 1.0):
        params = DenseParams(
            refine_head_pose=False, register_scan=False, temporal_sigma_s=0.0,
            smoothing_m=0.001, stereo_flow_weight=weight,
        ).for_source("stereo")  # fmt: skip
        dense = dense_track(
            color, matched, K, pose, vertices, faces, params, right=pair, fps=FPS
        )  # fmt: skip
        err = []
        for t in range(T):
            shift, dz = warp(uv0, t)
            true = backproject(uv0 + shift, neutral_depth(uv0) + dz, K)
            err.append(np.abs(vertices[:, 2] + dense.displacement[t, :, 2] - true[:, 2]))
        errors[weight] = float(np.median(err))
    print({w: f"{e * 1e3:.3f} mm" for w, e in errors.items()})
    assert errors[0.0] > 0.2e-3  # the matched depth's noise, smoothed by the local fit
    assert errors[1 / 3] < 0.85 * errors[0.0]
    assert errors[1.0] < 0.6 * errors[0.0]


def test_the_disparity_change_gives_the_depth_change_where_the_rows_agree():
    """A rectified pair at 0.5 m (f_x B = 30 px m, no principal-point offset: 60 px of
    disparity): the left image's skin moves 1 px to the right, the right image's stays, so
    the disparity grows to 61 px and the depth becomes 30 / 61 m. Where the right flow also
    moves 0.8 px vertically and the left one does not, the rows disagree beyond the 0.5 px
    tolerance: no depth change is read there."""
    from physanim.tracking.dense import _RightFlow

    h, w = 20, 40
    neutral = np.full((h, w), 0.5, np.float32)
    forward = np.zeros((h, w, 2), np.float32)
    forward[..., 0] = 1.0
    right = np.zeros((h, w + 60, 2), np.float32)  # its column 0 is the left's column -60
    right[10:, :, 1] = 0.8
    change = _RightFlow(right, -60, 30.0, 0.0).depth_change(forward, neutral, 0.5)
    np.testing.assert_allclose(change[:10], 30.0 / 61.0 - 0.5, rtol=1e-5)
    assert np.isnan(change[10:]).all()


def test_the_depth_change_window_follows_the_source_unless_set():
    """A stereo pair's depth is noisier than a depth camera's: an unset window of the depth
    change's fit takes the wider default there; a window that is set stays."""
    params = DenseParams()
    assert params.depth_change_sigma_px is None
    assert params.for_source("stereo").depth_change_sigma_px == DEPTH_CHANGE_SIGMA_PX["stereo"]
    for kind in ("bag", "rgbd"):
        assert params.for_source(kind).depth_change_sigma_px == DEPTH_CHANGE_SIGMA_PX["depth"]
    assert DEPTH_CHANGE_SIGMA_PX["stereo"] > DEPTH_CHANGE_SIGMA_PX["depth"]
    assert DenseParams(depth_change_sigma_px=3.0).for_source("stereo").depth_change_sigma_px == 3.0


def test_a_face_that_never_rests_after_the_neutral_frame_is_warned_about():
    """The whole grid moves from frame 1 on (a sway that never returns): no vertex rests, so
    nothing is taken out and the dense stage's summary warns; the same grid that stays
    still after frame 0 rests everywhere and gets no warning."""
    from physanim.tracking.dense import DenseObservations, without_neutral_error
    from tasks.dense import _neutral_summary

    n, T = 21, 30
    vertices, faces = _grid(n)
    rng = np.random.default_rng(5)
    noise = np.stack([_smooth_noise(rng, vertices, np.full(3, 0.05e-3)) for _ in range(T)])
    sway = 0.002 * np.sin(np.pi * np.arange(T) / (T - 1) / 2)  # 0 -> 2 mm, never back
    poses = np.tile(np.eye(4), (T, 1, 1))
    for motion, rests in ((sway, False), (0.0 * sway, True)):
        observed = noise - noise[0]
        observed[:, :, 0] += motion[:, None]
        obs = DenseObservations(np.ones(n * n, bool), observed, np.zeros((T, n * n)), poses, 0.0)
        taken, neutral = without_neutral_error(obs, vertices, faces, DenseParams(), fps=FPS)
        summary = _neutral_summary(neutral)
        if rests:
            assert neutral.resting_fraction > 0.95 and "warnings" not in summary
        else:
            assert (
                neutral.resting_fraction < 0.05
                and "rests in any later frame" in summary["warnings"][0]
            )
            np.testing.assert_allclose(taken.displacement, observed, atol=2e-5)

"""Dense capture: the motion of every vertex of the bound scan from each frame's colour and depth.

Scene flow from optical flow plus depth, registered to the neutral frame so errors do not
accumulate (Beeler et al. 2011 track against anchor frames for the same reason):

1. **Neutral view.** The scan (actor frame, N vertices) is posed by the landmark tracker's head
   pose at frame 0, registered to the neutral depth (``physanim.tracking.register``: the
   pose then comes from the surface, so biased markerless landmarks do not misplace the scan;
   the tracker's poses of the other frames get the same correction) and projected; a vertex
   is *seen* where the measured depth agrees with its
   own (``visible_tolerance_m``) and the surface faces the camera (``min_cos_view``). Its
   neutral position is lifted from the measured depth, so a constant offset between the scan
   and the measured surface cancels from the motion.
2. **Flow.** OpenCV's DIS optical flow from the neutral colour frame to frame t, and back, in
   the window the face reaches under the tracker's head poses (:func:`flow_window`), each
   started from the same direction's flow of frame t - 1, so a large motion (a jaw drop on
   lips without painted dots) is reached in steps: the held-out vowels rendered without
   markers read 0.222 at the jaw drop with every flow started from rest, 0.199 so started
   (0.151 with markers). The flow matches each image's local contrast, not its brightness
   (:func:`flow_image`): skin that turns under the light grows brighter or darker, which led
   brightness-matching flow astray (the library's RGB-D peaks: mean 0.119 -> 0.114; the
   held-out vowels without markers 0.198 -> 0.128 at the jaw drop). The flow runs on the
   images enlarged twice (``flow_upsample``) with patches of 3 camera pixels, its field then
   averaged back to the camera's pixels: finer patches blur the skin's motion less where it
   changes fast (the library's RGB-D peaks: mean 0.114 -> 0.110 on the performances it was
   chosen on, 0.117 -> 0.113 on the held-out ones). Each flow runs in two passes
   (``flow_passes``, :func:`dis_flow`): one DIS pass read 8-10 % too little of a lip
   press's motion on the skin's faint texture; the second, from the frame warped back by
   the first, reads most of the rest (the RGB-D peaks: mean 0.0715 -> 0.0673 on the
   performances it was chosen on, 0.0724 -> 0.0695 on the held-out ones). The vertex's pixel at t
   is its neutral pixel plus the forward flow, averaged with the backward flow's estimate
   (``flow_two_way``). Where the backward flow does not return it within
   ``max_flow_error_px`` (occlusion, the inside of the open mouth, flow failure) the vertex
   is not observed at t.
3. **Lift.** The vertex's neutral depth (Gaussian-smoothed with invalid pixels left out)
   plus the change of depth at its neutral pixel gives the camera-frame point; motion
   towards the camera (a pucker) comes from depth directly. The change (frame t's depth
   pulled back by the flow, minus the neutral's) is read from a quadratic fitted to it
   around the pixel (:func:`physanim.tracking.local_fit.local_polynomial`,
   ``depth_change_degree``): a weighted mean flattened the peak of the lips' motion (the
   library's RGB-D peaks: mean 0.110 -> 0.100 on the performances it was chosen on, 0.113 ->
   0.103 on the held-out ones). From a stereo pair the change is also read from the change of
   disparity between the left image's flow and the right image's flow at the same skin
   (:class:`_RightFlow`; a third DIS flow, neutral to t in the right image), and the two
   changes are averaged, the flows' with weight ``stereo_flow_weight``: the matched (SGBM)
   depth errs where the skin's texture shifts under its blocks, the flows where their
   disparity does, and the two errors are independent (the library's stereo peaks: mean
   0.125 -> 0.117 on the performances it was chosen on, 0.131 -> 0.123 on the held-out
   ones). The right flow counts only where its vertical motion agrees with the left one's
   (``stereo_row_tolerance_px``): the pair's rows are shared.
4. **Head pose.** Re-estimated from the dense points with the landmark tracker's robust
   weighted Kabsch (``physanim.tracking.tracks.head_poses``): points that ride rigidly with
   the head over the sequence dominate, so an expression does not tilt the head. Then
   refined with each point's depth weighted ``pose_depth_weight`` against its image
   position (``refine_poses_anisotropic``): depth is the noisier coordinate (flow places a
   vertex to about 0.2 mm in the image; its depth change errs by 0.5-0.8 mm), and a cheek
   puffed towards the camera moves only in depth; counted in full, it tilted the pose by
   0.8 degrees from a stereo pair (cheeks-s0's puff: 0.295 -> 0.186 with the weight 0.1).
5. **The neutral frame's error.** Every frame's depth change and flow are read against the
   neutral frame, so that frame's own noise (0.12 mm RMS in depth from the library's RGB-D
   frames) is shared by all of them, and smoothing over time cannot lower it. Where a vertex
   rests (:func:`neutral_error`) its observed motion is that shared error plus the frame's
   own; their mean over its rest frames is subtracted from every frame (the library's RGB-D
   peaks: mean 0.091 -> 0.084 on the performances it was chosen on, 0.093 -> 0.084 on the
   held-out ones).
   Then each frame's head pose is corrected by the skin that rests in it
   (:func:`rest_pose`): step 4 weighs a point by how rigidly it rides with the head over the
   whole sequence, so an expression that moves much of the face tilts that frame's pose by a
   few hundredths of a degree (the library's RGB-D peaks: mean 0.0673 -> 0.0668 on the
   performances it was chosen on, 0.0695 -> 0.0649 on the held-out ones).
6. **Fill and smooth.** Per frame, the displacement field u minimises
   ``sum_i c_i |u_i - u_obs_i|^2 + lam * sum_edges |(u_i - u_j) - w_ij (p_i - p_j)|^2`` over
   the (lip-cut) scan graph, c_i = 1 where observed, p the prior (the kinematic scan's
   motion, or 0) and w_ij = 1 on the edges that touch a vertex the neutral frame does not
   see, else 0: observed motion is smoothed over ``smoothing_m`` and every unobserved vertex
   is filled harmonically from its neighbours, an unseen one following the prior's shape
   (the seam keeps the lips apart). Observations farther than ``outlier_m`` from the
   smoothed field are dropped and the field solved again. Then each vertex's motion is
   smoothed over time by a quadratic fitted around each frame (``temporal_degree``,
   ``temporal_sigma_s``): a Gaussian mean flattened the expressions' peaks (with the smoothing
   on the scan halved to 0.5 mm, the library's RGB-D peaks: mean 0.100 -> 0.091 on the
   performances it was chosen on, 0.103 -> 0.093 on the held-out ones). Where the
   prior folds the surface over unseen vertices (the kinematic scan at the inner mouth
   corner in a smile), those vertices follow their neighbours' motion instead
   (:func:`unfold_unseen`).

The confidence (T, N) is 1 where a vertex was observed and kept, 0 where it was filled: a
filled vertex is marked, never silently guessed.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace

import cv2
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.ndimage import minimum_filter1d

from physanim.capture.frames import StereoRight
from physanim.mesh.topology import uniform_laplacian, vertex_normals
from physanim.tracking.dense_params import DenseParams
from physanim.tracking.lift import backproject, sample
from physanim.tracking.local_fit import local_polynomial, polynomial_in_time
from physanim.tracking.register import Registration, register_to_depth
from physanim.tracking.tracks import head_poses, refine_poses_anisotropic
from physanim.transforms import fit_transform, rotation_angle_deg

#: About how many of the seen vertices (every k-th) re-estimate the head pose.
POSE_POINTS = 3000
#: Fewest resting vertices from which :func:`rest_pose` corrects a frame's head pose.
POSE_REST_POINTS = 100
#: Least spread (m, the resting points' second principal standard deviation) from which
#: :func:`rest_pose` corrects a frame's pose: a narrow strip fixes a rotation about its own
#: axis poorly. The library's frames rest over 14-22 mm.
POSE_REST_SPREAD_M = 0.005
#: Most passes of :func:`rest_pose` (each finds the rest in the motion the one before corrected).
POSE_REST_PASSES = 3
#: Columns (px) the right image's flow window of a stereo pair extends beyond the neutral
#: frame's disparities, for the change of disparity of an expression (a few px).
STEREO_MARGIN_PX = 8
#: Least local standard deviation (8-bit levels) that :func:`flow_image` divides by: flat,
#: dark places (the open mouth's shadow) would otherwise become amplified sensor noise
#: (with 2 levels and 8 px, the flow of jaw_side-s0 lost a lip corner for five frames).
CONTRAST_FLOOR = 5.0
#: 8-bit levels per local standard deviation in :func:`flow_image`'s output (about three
#: deviations each side of mid-grey).
CONTRAST_GAIN = 40.0


@dataclass(frozen=True)
class NeutralError:
    """What :func:`without_neutral_error` took out: the ``rms_m`` of the shared error over the
    seen vertices that rest in some frame (m), and the ``resting_fraction`` of the seen
    vertices that do (the others keep their observed motion)."""

    rms_m: float
    resting_fraction: float


@dataclass(frozen=True)
class DenseMotion:
    """Dense capture of T frames of N scan vertices.

    ``displacement`` (T, N, 3) float32 m in the actor (head) frame, relative to frame 0;
    ``confidence`` (T, N) float32 in [0, 1], 0 where the vertex was filled from neighbours;
    ``head_pose`` (T, 4, 4) camera <- actor, m; ``seen`` (N,) bool, seen in the neutral
    frame; ``flow_error_px`` (T,) median forward-backward flow disagreement of the seen
    vertices; ``seconds_per_frame`` wall time of the flow, lifting and filling per frame;
    ``neutral`` the neutral frame's error taken out (:func:`without_neutral_error`);
    ``registration`` of the scan to the neutral depth (None when not asked for);
    ``unfolded`` how many (frame, vertex) pairs :func:`unfold_unseen` filled anew;
    ``pose_correction_deg`` (T,) the angle by which :func:`rest_pose` turned each frame's
    head pose (degrees; None when not asked for).
    """

    displacement: NDArray
    confidence: NDArray
    head_pose: NDArray
    seen: NDArray
    flow_error_px: NDArray
    seconds_per_frame: float
    neutral: NeutralError
    registration: Registration | None = None
    unfolded: int = 0
    pose_correction_deg: NDArray | None = None


def smooth_depth(depth: NDArray, sigma_px: float) -> NDArray:
    """Gaussian-smoothed depth (H, W) float32 m, invalid (NaN or <= 0) pixels left out
    (normalised convolution); NaN where less than half the kernel's weight is valid."""
    return blur_valid(depth, np.isfinite(depth) & (depth > 0), sigma_px)


def blur_valid(values: NDArray, valid: NDArray, sigma_px: float) -> NDArray:
    """Gaussian blur (H, W) float32 of ``values`` over the ``valid`` (H, W) pixels only
    (normalised convolution); NaN where less than half the kernel's weight is valid."""
    if sigma_px <= 0:
        return np.where(valid, values, np.nan).astype(np.float32)
    num = cv2.GaussianBlur(np.where(valid, values, 0.0).astype(np.float32), (0, 0), sigma_px)
    den = cv2.GaussianBlur(valid.astype(np.float32), (0, 0), sigma_px)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = num / den
    out[den < 0.5] = np.nan
    return out


def flow_image(gray: NDArray, sigma_px: float) -> NDArray:
    """The image (H, W) uint8 the flow matches: ``gray`` (H, W) uint8 itself, or with
    ``sigma_px`` > 0 its local contrast (minus the local mean, over the local standard
    deviation, both Gaussian over ``sigma_px``), which does not change where a turning surface
    is lit more or less brightly. The standard deviation is floored at ``CONTRAST_FLOOR``."""
    if sigma_px <= 0:
        return np.ascontiguousarray(gray)
    g = gray.astype(np.float32)
    mean = cv2.GaussianBlur(g, (0, 0), sigma_px)
    var = cv2.GaussianBlur(g * g, (0, 0), sigma_px) - mean * mean
    z = (g - mean) / np.sqrt(np.maximum(var, 0.0) + CONTRAST_FLOOR**2)
    return np.clip(128.0 + CONTRAST_GAIN * z, 0, 255).astype(np.uint8)


def _enlarge(image: NDArray, params: DenseParams) -> NDArray:
    """``image`` (H, W) enlarged ``params.flow_upsample`` times (cubic) for the flow."""
    u = params.flow_upsample
    return image if u == 1 else cv2.resize(image, None, fx=u, fy=u, interpolation=cv2.INTER_CUBIC)


def _reduce(flow: NDArray, shape: tuple[int, ...], params: DenseParams) -> NDArray:
    """A flow field of the enlarged images back at the camera's pixels (``shape`` (H, W)):
    each pixel's enlarged pixels averaged, the motion in camera pixels."""
    u = params.flow_upsample
    if u == 1:
        return flow
    return cv2.resize(flow, (shape[1], shape[0]), interpolation=cv2.INTER_AREA) / u


def _project(points: NDArray, K: NDArray) -> NDArray:
    """Pixels (P, 2) of camera-frame points (P, 3) m."""
    p = points @ K.T
    return p[:, :2] / p[:, 2:3]


def _transform(pose: NDArray, points: NDArray) -> NDArray:
    return points @ pose[:3, :3].T + pose[:3, 3]


def _flow_engine(params: DenseParams) -> cv2.DISOpticalFlow:
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    dis.setFinestScale(params.flow_finest_scale)
    dis.setPatchSize(params.flow_patch_px)
    dis.setPatchStride(min(params.flow_stride_px, params.flow_patch_px))
    dis.setGradientDescentIterations(params.flow_iterations)
    dis.setVariationalRefinementIterations(params.flow_refinement_iterations)
    dis.setVariationalRefinementAlpha(params.flow_smoothness)
    dis.setVariationalRefinementDelta(params.flow_constancy_weight)
    return dis


def dis_flow(
    engine: cv2.DISOpticalFlow, source: NDArray, target: NDArray, start: NDArray | None,
    passes: int, max_left_px: float,
) -> NDArray:  # fmt: skip
    """Flow (H, W, 2) px from ``source`` to ``target`` (H, W) uint8 by ``engine``, started
    from ``start`` (H, W, 2) px or rest. Each pass after the first warps ``target`` back by
    the flow so far and composes the flow that is left: one DIS pass on skin's faint texture
    reads a motion that changes over a few pixels short (its coarse levels average the moving
    lips with the skin at rest, and its fine patches find too little texture to correct
    them), the next pass starts from a nearly aligned pair and reads most of the rest. What
    is left is small where the first pass held; where a later pass finds more than
    ``max_left_px`` it has lost the match (left in, such remainders made medley-s0's
    flows disagree forward and backward by up to 3.6e5 px), and the flow so far stands."""
    flow = engine.calc(source, target, start)
    if passes == 1:
        return flow
    h, w = source.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    for _ in range(passes - 1):
        warped = cv2.remap(
            target, xs + flow[..., 0], ys + flow[..., 1], cv2.INTER_CUBIC,
            borderMode=cv2.BORDER_REPLICATE,
        )  # fmt: skip
        left = engine.calc(source, warped, None)
        left[~(np.hypot(left[..., 0], left[..., 1]) <= max_left_px)] = 0.0
        # a pixel x of the source lands at x + left(x) in the warped target, which is
        # the target's pixel (x + left(x)) + flow(x + left(x))
        moved = cv2.remap(
            flow, xs + left[..., 0], ys + left[..., 1], cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )  # fmt: skip
        flow = left + moved
    return flow


@dataclass(frozen=True)
class _NeutralView:
    """Seen vertices' neutral pixels ``uv`` (S, 2), smoothed depth ``z`` (S,) m, ``points``
    (S, 3) m actor frame, and the neutral frame's ``raw_depth`` (H, W) m (NaN invalid)."""

    seen: NDArray
    uv: NDArray
    z: NDArray
    points: NDArray
    raw_depth: NDArray


def neutral_view(
    vertices: NDArray, faces: NDArray, K: NDArray, pose: NDArray, depth: NDArray,
    raw_depth: NDArray, params: DenseParams,
) -> _NeutralView:  # fmt: skip
    """Which scan vertices (N, 3) m actor frame the neutral frame sees (camera <- actor
    ``pose`` (4, 4), smoothed ``depth`` and ``raw_depth`` (H, W) m), their pixels and measured
    positions."""
    cam = _transform(pose, vertices)
    normals = vertex_normals(vertices, faces) @ pose[:3, :3].T
    view = cam / np.linalg.norm(cam, axis=1, keepdims=True)
    facing = -(normals * view).sum(axis=1) > params.min_cos_view
    uv = _project(cam, K)
    z = sample(depth, uv)
    with np.errstate(invalid="ignore"):
        seen = facing & (np.abs(z - cam[:, 2]) < params.visible_tolerance_m)
    measured = backproject(uv[seen], z[seen], K)
    inv = np.linalg.inv(pose)
    raw = np.where(raw_depth > 0, raw_depth, np.nan).astype(np.float32)
    return _NeutralView(seen, uv[seen], z[seen], _transform(inv, measured), raw)


def flow_window(
    points: NDArray, head_pose: NDArray, K: NDArray, shape: tuple[int, ...], margin_px: int
) -> tuple[int, int, int, int]:
    """Pixel window (x0, y0, x1, y1), end exclusive, of an image of ``shape`` (H, W) that
    holds the actor-frame ``points`` (P, 3) m under every head pose (T, 4, 4) camera <- actor,
    widened by ``margin_px`` on each side for the expressions' own motion."""
    cam = np.einsum("tij,pj->tpi", head_pose[:, :3, :3], points) + head_pose[:, None, :3, 3]
    uv = _project(cam.reshape(-1, 3), K)
    uv = uv[np.isfinite(uv).all(axis=1)]
    h, w = shape[:2]
    lo = np.floor(uv.min(axis=0)) - margin_px
    hi = np.ceil(uv.max(axis=0)) + margin_px + 1
    x0, y0 = (int(np.clip(v, 0, m)) for v, m in zip(lo, (w, h), strict=True))
    x1, y1 = (int(np.clip(v, 0, m)) for v, m in zip(hi, (w, h), strict=True))
    return x0, y0, x1, y1


@dataclass(frozen=True)
class _RightFlow:
    """One frame's flow ``flow`` (H, W', 2) px from the neutral frame in the right image of a
    rectified pair, in a window whose column 0 is the left window's column ``shift`` px (the
    rows are shared); ``fx_baseline`` px m and ``doffs`` px as in ``StereoRight``."""

    flow: NDArray
    shift: int
    fx_baseline: float
    doffs: float

    def depth_change(
        self, forward: NDArray, neutral_depth: NDArray, row_tolerance: float
    ) -> NDArray:
        """Change of depth (H, W) m at each pixel of the left window from the neutral frame
        (``neutral_depth`` (H, W) m, NaN invalid) to this one, from the change of disparity
        between the left window's ``forward`` flow (H, W, 2) px and this flow at the same
        skin's pixel of the right image. NaN where either is unknown or where the two flows'
        vertical motions differ by more than ``row_tolerance`` px: the pair's rows are
        shared, so that difference is the flows' own error."""
        h, w = neutral_depth.shape
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        disparity = self.fx_baseline / neutral_depth - self.doffs
        right = cv2.remap(
            self.flow, xs - disparity - self.shift, ys, cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT, borderValue=(np.nan, np.nan),
        )  # fmt: skip
        moved = disparity + forward[..., 0] - right[..., 0]
        change = self.fx_baseline / (moved + self.doffs) - neutral_depth
        with np.errstate(invalid="ignore"):
            change[~(np.abs(forward[..., 1] - right[..., 1]) <= row_tolerance)] = np.nan
        return change


def _frame_points(
    forward: NDArray, backward: NDArray, depth: NDArray, view: _NeutralView, K: NDArray,
    params: DenseParams, right: _RightFlow | None = None,
) -> tuple[NDArray, NDArray]:  # fmt: skip
    """Camera-frame points (S, 3) m of the seen vertices in one frame (NaN where not
    observed) and their forward-backward flow disagreement (S,) px, from the flow (H, W, 2)
    px from the neutral frame to it (``forward``) and back (``backward``) and its depth;
    from a stereo pair also the ``right`` image's flow (``params.stereo_flow_weight``)."""
    uv = view.uv + sample(forward, view.uv)
    back = uv + sample(backward, uv)
    fb = np.linalg.norm(back - view.uv, axis=1)
    if params.flow_two_way:
        # the backward flow's own estimate of the pixel is the forward one moved back by the
        # disagreement; their mean averages the two flows' independent errors
        uv = uv - 0.5 * (back - view.uv)
    # the change of depth, pulled back to the neutral frame's pixels by the flow, is smooth
    # where the depth itself is not (lip edges, the nose tip): smoothed, it is not biased there.
    # Pixels whose flow does not come back (occluded or disoccluded: the inside of an opening
    # mouth) are left out of that smoothing, so the cavity's depth does not leak onto the lips.
    h, w = depth.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    to_x, to_y = xs + forward[..., 0], ys + forward[..., 1]
    pulled = cv2.remap(
        np.where(depth > 0, depth, np.nan).astype(np.float32), to_x, to_y, cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan,
    )  # fmt: skip
    returned = cv2.remap(
        backward, to_x, to_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
        borderValue=(np.nan, np.nan),
    )  # fmt: skip
    consistent = np.hypot(*np.moveaxis(forward + returned, -1, 0)) < params.max_flow_error_px
    change = pulled - view.raw_depth
    if right is not None and params.stereo_flow_weight > 0:
        w = params.stereo_flow_weight
        other = right.depth_change(forward, view.raw_depth, params.stereo_row_tolerance_px)
        both = np.isfinite(change) & np.isfinite(other)
        change = np.where(both, (1 - w) * change + w * other, np.fmax(change, other))
    valid = np.isfinite(change) & consistent
    sigma = params.depth_change_sigma_px  # resolved by observe (DenseParams.for_source)
    if params.depth_change_degree == 0:
        z = view.z + sample(blur_valid(change, valid, sigma), view.uv)
    else:
        z = view.z + local_polynomial(change, valid, sigma, view.uv, params.depth_change_degree)
    points = backproject(uv, z, K)
    with np.errstate(invalid="ignore"):
        points[~(fb < params.max_flow_error_px)] = np.nan
    return points, fb


def _smoother(laplacian: sp.csr_array, seen: NDArray, lam: float) -> Callable[[NDArray], NDArray]:
    """``solve(b)`` for (S_seen + lam L) u = b on the scan graph, factorised once (PARDISO
    where MKL loads, else CHOLMOD, else SuperLU; a block solve over the frames' columns);
    S_seen the 0/1 diagonal of the seen vertices, L the graph ``laplacian`` (N, N). b (N, k)."""
    from physanim.fem.linsolve import factorize_many as factorize

    n = len(seen)
    A = laplacian * lam + sp.diags_array(seen.astype(np.float64))
    # a tiny diagonal keeps pieces without any seen vertex (islands of the scan) regular
    return factorize(sp.csc_matrix(A + sp.identity(n) * 1e-9 * lam))


def _laplacian_of_edges_touching(laplacian: sp.csr_array, touching: NDArray) -> sp.csr_array:
    """The graph Laplacian (N, N) of the edges of ``laplacian``'s graph with at least one end
    among the ``touching`` (N,) vertices."""
    adjacency = -sp.triu(laplacian, k=1).tocoo()
    keep = touching[adjacency.row] | touching[adjacency.col]
    i, j = adjacency.row[keep], adjacency.col[keep]
    n = laplacian.shape[0]
    a = sp.csr_array((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(n, n))
    return (sp.diags_array(np.asarray(a.sum(axis=1)).ravel()) - a).tocsr()


def _induced_laplacian(faces: NDArray, keep: NDArray) -> sp.csr_array:
    """Graph Laplacian (K, K) of the scan graph restricted to the ``keep`` (N,) vertices."""
    inside = faces[keep[faces].all(axis=1)]
    renumber = np.cumsum(keep) - 1
    return uniform_laplacian(renumber[inside], int(keep.sum()))


def _harmonic_fill(laplacian: sp.csr_array, known: NDArray, values: NDArray) -> NDArray:
    """``values`` (K, 3) with the entries not ``known`` (K,) replaced by the harmonic
    extension of the known ones over the graph (0 on pieces without a known vertex)."""
    unknown = ~known
    out = np.where(known[:, None], values, 0.0)
    if not unknown.any():
        return out
    from scipy.sparse.linalg import splu

    A = laplacian[unknown][:, unknown] + sp.identity(int(unknown.sum())) * 1e-9
    b = -(laplacian[unknown][:, known] @ values[known])
    out[unknown] = splu(sp.csc_matrix(A)).solve(b)
    return out


def _edge_length(vertices: NDArray, faces: NDArray) -> float:
    e = vertices[faces[:, [1, 2, 0]]] - vertices[faces]
    return float(np.median(np.linalg.norm(e, axis=2)))


@dataclass(frozen=True)
class DenseObservations:
    """What the frames show of the seen vertices (S of the scan's N): ``seen`` (N,) bool;
    ``displacement`` (T, S, 3) m actor frame relative to frame 0, NaN where not observed;
    ``flow_error_px`` (T, S) forward-backward flow disagreement; ``head_pose`` (T, 4, 4)
    camera <- actor; ``seconds`` wall time; ``registration`` of the scan to the neutral
    depth (None when not asked for)."""

    seen: NDArray
    displacement: NDArray
    flow_error_px: NDArray
    head_pose: NDArray
    seconds: float
    registration: Registration | None = None


def observe(
    color: NDArray,
    depth: NDArray,
    K: NDArray,
    head_pose: NDArray,
    vertices: NDArray,
    faces: NDArray,
    params: DenseParams,
    progress: Callable[[int, int], None] | None = None,
    right: StereoRight | None = None,
) -> DenseObservations:
    """Flow, lifting and head pose (steps 1-4 of the module docstring) for the scan
    ``vertices`` (N, 3) m actor frame, ``faces`` (F, 3), from ``color`` (T, H, W, 3) uint8
    RGB and ``depth`` (T, H, W) m (NaN or 0 invalid; Zarr arrays are read a frame at a
    time), intrinsics ``K`` (3, 3) px and the landmark tracker's ``head_pose`` (T, 4, 4)
    camera <- actor; from a stereo pair (``color`` its left images) also the ``right``
    images. Frame 0 is the neutral. With ``params.register_scan`` the scan is
    registered to the neutral depth and every tracker pose gets the correction of frame 0's;
    a registration that keeps fewer than half the scan's facing points is not applied. An
    unset ``depth_change_sigma_px`` is the depth frames' (``DenseParams.for_source`` sets a
    recording's)."""
    params = params.for_source("rgbd")  # leaves a set depth_change_sigma_px as it is
    T = color.shape[0]
    start = time.perf_counter()
    shape = tuple(color.shape[1:3])  # (H, W) px
    depth0 = smooth_depth(np.asarray(depth[0], dtype=np.float32), params.depth_sigma_px)
    head_pose = np.asarray(head_pose, dtype=np.float64)
    registration = None
    if params.register_scan:
        registration = register_to_depth(
            vertices, vertex_normals(vertices, faces), depth0, K, head_pose[0],
            params.register_max_distance_m, params.visible_tolerance_m,
        )  # fmt: skip
        if registration.converged:
            head_pose = head_pose @ (np.linalg.inv(head_pose[0]) @ registration.pose)
    view = neutral_view(
        vertices, faces, K, head_pose[0], depth0, np.asarray(depth[0], np.float32), params
    )
    if view.seen.sum() < 3:
        raise ValueError(
            "dense capture: the neutral frame sees fewer than 3 scan vertices; check the head "
            "pose of frame 0 (stage track) and the depth of the recording"
        )
    # the flow is computed in the window the face can reach (a face fills a fifth of a
    # 640 x 480 frame: 8x less work than the whole frame, and no background to match)
    x0, y0, x1, y1 = flow_window(vertices[view.seen], head_pose, K, shape, params.flow_margin_px)
    shift = None
    if right is not None and params.stereo_flow_weight > 0:
        # the right image's window: the left one moved by the neutral's disparities
        disparity = right.fx_baseline / view.z - right.doffs
        rx0 = int(np.clip(x0 - np.ceil(disparity.max()) - STEREO_MARGIN_PX, 0, x1))
        rx1 = int(np.clip(x1 - np.floor(disparity.min()) + STEREO_MARGIN_PX, rx0, shape[1]))
        shift = rx0 - x0

    def flow_input(image: NDArray, a: int, b: int) -> NDArray:
        gray = cv2.cvtColor(np.asarray(image)[y0:y1, a:b], cv2.COLOR_RGB2GRAY)
        return _enlarge(flow_image(gray, params.flow_normalise_px), params)

    gray0 = flow_input(color[0], x0, x1)
    right0 = None if shift is None else flow_input(right.color[0], rx0, rx1)
    K_window = K.copy()
    K_window[0, 2] -= x0
    K_window[1, 2] -= y0
    view_window = replace(
        view, uv=view.uv - [x0, y0], raw_depth=view.raw_depth[y0:y1, x0:x1].copy()
    )
    workers = min(2, params.workers or len(os.sched_getaffinity(0)))
    # one DIS engine per direction (an engine is not thread-safe), each used by one call at a
    # time: frame t + 1's flows (started from frame t's) run while frame t's points are lifted
    # (and one for the right image's forward flow)
    engines = [_flow_engine(params) for _ in range(2 if shift is None else 3)]

    def flows(t: int, pool: ThreadPoolExecutor, start: list[NDArray] | None) -> list[Future]:
        gray = flow_input(color[t], x0, x1)
        pairs = [(gray0, gray), (gray, gray0)]
        if shift is not None:
            pairs.append((right0, flow_input(right.color[t], rx0, rx1)))
        # passes and the largest remainder a later pass may add (enlarged pixels)
        n, left = params.flow_passes, params.max_flow_error_px * params.flow_upsample
        return [
            pool.submit(dis_flow, engine, a, b, None if start is None else start[i].copy(), n, left)
            for i, (engine, (a, b)) in enumerate(zip(engines, pairs, strict=True))
        ]

    cam = np.full((T, len(view.uv), 3), np.nan)
    fb = np.full((T, len(view.uv)), np.nan)
    with ThreadPoolExecutor(workers) as pool:
        pending = flows(0, pool, None)
        for t in range(T):
            done = [job.result() for job in pending]
            if t + 1 < T:
                pending = flows(t + 1, pool, done)
            frame_depth = np.asarray(depth[t], dtype=np.float32)[y0:y1, x0:x1]
            right_flow = None
            if shift is not None:
                right_flow = _RightFlow(
                    _reduce(done[2], (y1 - y0, rx1 - rx0), params), shift, right.fx_baseline,
                    right.doffs,
                )  # fmt: skip
            cam[t], fb[t] = _frame_points(
                _reduce(done[0], frame_depth.shape, params),
                _reduce(done[1], frame_depth.shape, params),
                frame_depth, view_window, K_window, params, right_flow,
            )  # fmt: skip
            if progress is not None:
                progress(t + 1, T)
    poses = head_pose
    if params.refine_head_pose:
        # a rigid pose needs a few thousand well-spread points, not every vertex (20k on the
        # demo: 3.4 s of the stage's 14 s went to the pose)
        every = slice(None, None, max(1, len(view.points) // POSE_POINTS))
        observed = np.isfinite(cam[:, every]).all(axis=2).astype(np.float64)
        poses = head_poses(cam[:, every], observed, view.points[every])
        if params.pose_depth_weight < 1.0:
            poses = refine_poses_anisotropic(
                cam[:, every], observed, view.points[every], poses,
                (1.0, 1.0, params.pose_depth_weight),
            )  # fmt: skip
        lost = ~np.isfinite(poses[:, 0, 0])
        poses[lost] = head_pose[lost]
    inv = np.linalg.inv(poses)
    actor = np.einsum("tij,tkj->tki", inv[:, :3, :3], cam) + inv[:, None, :3, 3]
    return DenseObservations(
        view.seen, actor - view.points[None], fb, poses, time.perf_counter() - start,
        registration,
    )  # fmt: skip


def _resting(
    obs: DenseObservations,
    faces: NDArray,
    params: DenseParams,
    edge_m: float,
    fps: float,
    factor: float,
) -> NDArray:
    """(T - 1, S) bool: where each seen vertex rests in frames 1.. (:func:`neutral_error`'s
    rule at ``factor`` times the smoothed motion's noise)."""
    T, S = obs.displacement.shape[:2]
    observed = np.isfinite(obs.displacement).all(axis=2)[1:]  # (T - 1, S)
    from physanim.fem.linsolve import factorize_many

    values = np.where(observed[..., None], obs.displacement[1:], 0.0)
    lam = (params.rest_smoothing_m / edge_m) ** 2
    smoother = sp.identity(S) + lam * _induced_laplacian(faces, obs.seen)
    columns = np.concatenate([values.transpose(1, 0, 2).reshape(S, -1), observed.T], axis=1)
    smooth = factorize_many(sp.csc_matrix(smoother))(columns.astype(np.float64))
    share = np.maximum(smooth[:, 3 * (T - 1) :], 1e-6)  # (S, T - 1)
    local = smooth[:, : 3 * (T - 1)].reshape(S, T - 1, 3) / share[..., None]
    motion = np.linalg.norm(polynomial_in_time(local.transpose(1, 0, 2), 1.0, 0), axis=2)
    both = observed[2:] & observed[1:-1] & observed[:-2]
    second = np.linalg.norm(local[:, 2:] - 2 * local[:, 1:-1] + local[:, :-2], axis=2).T
    # the motion's own second differences are small at camera frame rates
    noise = np.median(second[both]) / np.sqrt(6.0) if both.any() else 0.0
    still = motion < factor * noise
    margin = int(round(params.rest_margin_s * fps))
    return observed & minimum_filter1d(still, 2 * margin + 1, axis=0, mode="nearest")


def neutral_error(
    obs: DenseObservations, faces: NDArray, params: DenseParams, edge_m: float, fps: float
) -> tuple[NDArray, NDArray]:
    """The error (S, 3) m that the observed motion of the seen vertices shares in every frame
    after the neutral: the neutral frame's own (its depth and colour, read once, enter
    each frame's depth change and flow); and how many frames each vertex rests in (S,).

    A seen vertex is at rest in frame t >= 1 where its observed motion, smoothed over
    ``rest_smoothing_m`` on the scan (normalised over the observed vertices) and over a
    frame in time, stays below ``rest_factor`` times that smoothed motion's noise in every
    frame within ``rest_margin_s`` of t (the margin keeps a motion's slow start and end
    out). The noise is the median over vertices and frames of its second difference over
    time / sqrt(6) (0.05-0.06 mm from the library's RGB-D frames): it does not assume that
    most of the face rests, which a median of the motion would (a warp of the whole image
    then read as rest). There its true motion is about 0 and its observed motion the shared
    error plus that frame's own, so their mean over its rest frames estimates the shared
    one; a vertex with no rest frame gets 0. ``edge_m`` the scan's median edge length (m),
    ``fps`` the frame rate (1/s)."""
    S = obs.displacement.shape[1]
    if params.rest_factor <= 0.0 or not np.isfinite(obs.displacement[1:]).all(axis=2).any():
        return np.zeros((S, 3)), np.zeros(S, dtype=np.int64)
    rest = _resting(obs, faces, params, edge_m, fps, params.rest_factor)
    values = np.where(rest[..., None], obs.displacement[1:], 0.0)
    count = rest.sum(axis=0)
    total = values.sum(axis=0)
    return np.where(count[:, None] > 0, total / np.maximum(count, 1)[:, None], 0.0), count


def without_neutral_error(
    obs: DenseObservations, vertices: NDArray, faces: NDArray, params: DenseParams, *, fps: float
) -> tuple[DenseObservations, NeutralError]:
    """The observations with :func:`neutral_error` taken out of every frame after the
    neutral (step 5 of the module docstring), for the scan ``vertices`` (N, 3) m / ``faces``
    (F, 3) at ``fps`` frames per second."""
    shared, count = neutral_error(obs, faces, params, _edge_length(vertices, faces), fps)
    motion = np.array(obs.displacement, dtype=np.float64)
    motion[1:] -= shared
    rests = count > 0
    rms = float(np.sqrt((shared[rests] ** 2).sum(axis=1).mean())) if rests.any() else 0.0
    resting = float(rests.mean()) if len(rests) else 0.0
    return replace(obs, displacement=motion), NeutralError(rms, resting)


def rest_pose(
    obs: DenseObservations, vertices: NDArray, faces: NDArray, params: DenseParams, *, fps: float
) -> tuple[DenseObservations, NDArray]:
    """The observations with each frame's head pose corrected by the skin that rests in it,
    and the correction's angle (T,) in degrees (0 where not corrected).

    The head pose of step 4 weighs every point by how rigidly it rides with the head over
    the whole sequence, so a frame whose expression moves much of the face tilts it a
    little: 0.04-0.09 degrees at the demo's smile and emotions-s0's nose wrinkle (from the
    truth), which moves the chin 0.1-0.2 mm. Per frame, the vertices at rest there
    (:func:`neutral_error`'s rule at the stricter ``pose_rest_factor``, applied to the
    motion with the neutral frame's error taken out) should not move: the rigid motion that
    best carries their neutral positions to their observed ones (Kabsch, at least
    ``POSE_REST_POINTS`` of them spread over ``POSE_REST_SPREAD_M``) is the pose's error and
    is taken out of every seen vertex's motion and folded into ``head_pose``. ``vertices``
    (N, 3) m / ``faces`` (F, 3) the scan, ``fps`` the frame rate (1/s)."""
    T = obs.displacement.shape[0]
    angles = np.zeros(T)
    if params.pose_rest_factor <= 0.0 or T < 2:
        return obs, angles
    points = vertices[obs.seen]
    edge = _edge_length(vertices, faces)
    motion, poses = obs.displacement, obs.head_pose
    rest = np.zeros((T - 1, len(points)), dtype=bool)
    for _ in range(POSE_REST_PASSES):
        # a tilt lifts the skin far from its axis above the rest threshold: each pass finds
        # the rest in the motion the pass before corrected
        found = _resting(
            replace(obs, displacement=motion), faces, params, edge, fps, params.pose_rest_factor
        )
        if (found == rest).all():
            break
        rest = found
        motion = np.array(obs.displacement, dtype=np.float64)
        poses = np.array(obs.head_pose, dtype=np.float64)
        angles = np.zeros(T)
        for t in range(1, T):
            use = rest[t - 1]
            if use.sum() < POSE_REST_POINTS or _spread(points[use]) < POSE_REST_SPREAD_M:
                continue
            fit = fit_transform(points[use], points[use] + motion[t, use], with_scale=False)
            rot, shift = fit.rotation, fit.translation
            # observed x = rot p' + shift for the corrected p': p' = rot^T (x - shift)
            motion[t] = (points + motion[t] - shift) @ rot - points
            correction = np.eye(4)
            correction[:3, :3], correction[:3, 3] = rot, shift
            poses[t] = poses[t] @ correction
            angles[t] = rotation_angle_deg(rot)
    return replace(obs, displacement=motion, head_pose=poses), angles


def _spread(points: NDArray) -> float:
    """The second principal standard deviation (m) of ``points`` (K, 3) m."""
    return float(np.sqrt(max(np.linalg.eigvalsh(np.cov(points.T))[1], 0.0)))


def fill_motion(
    obs: DenseObservations,
    vertices: NDArray,
    faces: NDArray,
    params: DenseParams,
    prior: NDArray | None = None,
    *,
    fps: float,
) -> tuple[NDArray, NDArray, int]:
    """Displacement (T, N, 3) float32 m and confidence (T, N) float32 of every scan vertex
    from the observations (step 6 of the module docstring), and how many (frame, vertex)
    pairs :func:`unfold_unseen` filled anew; ``fps`` the frame rate (1/s) that turns
    ``temporal_sigma_s`` into frames. With a ``prior`` (T, N, 3) m
    (the kinematic scan's motion), the observed departure from it fills the vertices no frame
    sees, so an unseen vertex keeps the prior's motion plus its neighbours' correction: the
    smoothness term is on the departure along the edges that touch an unseen vertex and on the
    motion itself between seen ones. Smoothing the departure everywhere kept the prior's own
    defects where the frames show better: the kinematic scan folds the eyelid crease at a brow
    raise (106 triangles turned over on brows-s1), and the observations there, 0.14 mm from
    the truth, could not unfold it through a smoothed departure (86 stayed turned)."""
    T, n = obs.displacement.shape[0], len(vertices)
    lam = max((params.smoothing_m / _edge_length(vertices, faces)) ** 2, 1e-3)
    laplacian = uniform_laplacian(faces, n)
    solve = _smoother(laplacian, obs.seen, lam)
    towards_unseen = _laplacian_of_edges_touching(laplacian, ~obs.seen)
    seen_idx = np.flatnonzero(obs.seen)
    seen_graph = _induced_laplacian(faces, obs.seen)
    observed = np.isfinite(obs.displacement).all(axis=2).T  # (S, T)
    base = np.zeros((T, n, 3)) if prior is None else np.asarray(prior, dtype=np.float64)
    # the departure from the prior at the seen vertices, (S, T, 3)
    measured = np.where(observed[..., None], obs.displacement.transpose(1, 0, 2), 0.0)
    measured -= base[:, seen_idx].transpose(1, 0, 2)
    prior_columns = base.transpose(1, 0, 2).reshape(n, T * 3)
    # (S + lam L) u = S (prior + du) + lam L_unseen prior: the motion u over (N, T, 3)
    prior_pull = lam * (towards_unseen @ prior_columns)
    keep = observed.copy()
    for _ in range(params.fill_iterations):
        # the seen vertices a frame does not observe (or observes as an outlier) get the
        # harmonic extension of the kept ones, so the smoother's weights stay those of the
        # seen vertices and one factorisation serves every frame
        du = np.stack([_harmonic_fill(seen_graph, keep[:, t], measured[:, t]) for t in range(T)], 1)
        rhs = prior_pull.copy()
        rhs[seen_idx] += prior_columns[seen_idx] + du.reshape(len(seen_idx), T * 3)
        fit = solve(rhs).reshape(n, T, 3) - base.transpose(1, 0, 2)  # the departure
        keep = observed & (np.linalg.norm(fit[seen_idx] - measured, axis=2) < params.outlier_m)
    displacement = base + fit.transpose(1, 0, 2)
    confidence = np.zeros((T, n), dtype=np.float32)
    confidence[:, seen_idx] = keep.T
    displacement = polynomial_in_time(
        displacement, params.temporal_sigma_s * fps, params.temporal_degree
    )
    displacement, unfolded = unfold_unseen(displacement, vertices, faces, obs.seen, laplacian)
    return displacement.astype(np.float32), confidence, unfolded


def unfold_unseen(
    displacement: NDArray,
    vertices: NDArray,
    faces: NDArray,
    seen: NDArray,
    laplacian: sp.csr_array,
    rings: int = 4,
) -> tuple[NDArray, int]:
    """``displacement`` (T, N, 3) m of the scan ``vertices`` (N, 3) m / ``faces`` (F, 3)
    with no triangle turned over (against frame 0) for want of an observation: per frame,
    the vertices no frame sees (``seen`` (N,) False) of every turned triangle, grown by up to
    ``rings`` rings of unseen neighbours until none is turned, take the harmonic extension
    of the others' motion over the scan graph (``laplacian`` (N, N)) instead of the prior's
    shape, which folded the inner mouth corner in medley-s1's smile (2 triangles). Triangles
    of seen vertices only are measured and left alone. Also returns how many (frame,
    vertex) pairs were filled anew."""
    unseen = ~np.asarray(seen, dtype=bool)
    candidates = faces[unseen[faces].any(axis=1)]
    if not len(candidates):
        return displacement, 0
    rest = vertices + displacement[0]
    rest_normal = _normals(rest, candidates)
    neighbours = (laplacian != 0).astype(np.int8)
    out, unfolded = displacement.copy(), 0
    for t in range(1, len(displacement)):
        moved = vertices + out[t]
        turned = (_normals(moved, candidates) * rest_normal).sum(axis=1) < 0.0
        if not turned.any():
            continue
        free = np.zeros(len(vertices), dtype=bool)
        for _ in range(rings + 1):
            free[candidates[turned].ravel()] = True
            free &= unseen
            out[t] = _harmonic_fill(laplacian, ~free, out[t])
            turned = (_normals(vertices + out[t], candidates) * rest_normal).sum(axis=1) < 0.0
            if not turned.any():
                break
            free |= (neighbours @ free.astype(np.int8)) > 0  # one more ring
        unfolded += int(free.sum())
    return out, unfolded


def _normals(points: NDArray, faces: NDArray) -> NDArray:
    """(F, 3) unnormalised normals of ``faces`` (F, 3) at ``points`` (N, 3)."""
    p = points[faces]
    return np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])


def dense_track(
    color: NDArray,
    depth: NDArray,
    K: NDArray,
    head_pose: NDArray,
    vertices: NDArray,
    faces: NDArray,
    params: DenseParams,
    prior: NDArray | None = None,
    progress: Callable[[int, int], None] | None = None,
    right: StereoRight | None = None,
    *,
    fps: float,
) -> DenseMotion:
    """Dense motion of the scan: :func:`observe`, :func:`without_neutral_error`,
    :func:`rest_pose`, then :func:`fill_motion` (arguments there)."""
    obs = observe(color, depth, K, head_pose, vertices, faces, params, progress, right)
    start = time.perf_counter()
    obs, neutral = without_neutral_error(obs, vertices, faces, params, fps=fps)
    obs, turned = rest_pose(obs, vertices, faces, params, fps=fps)
    displacement, confidence, unfolded = fill_motion(obs, vertices, faces, params, prior, fps=fps)
    with np.errstate(invalid="ignore"):
        flow_error = np.nanmedian(obs.flow_error_px, axis=1)
    seconds = obs.seconds + time.perf_counter() - start
    return DenseMotion(
        displacement, confidence, obs.head_pose, obs.seen, flow_error, seconds / color.shape[0],
        neutral, obs.registration, unfolded,
        turned if params.pose_rest_factor > 0 else None,
    )  # fmt: skip

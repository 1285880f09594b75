"""Depth from a calibrated stereo pair: rectification, SGBM, left-right check, optional WLS,
sub-pixel refinement (:mod:`physanim.capture.subpixel`).

Depth (m) along the rectified left camera's axis: ``z = f_x * B / (d + doffs)`` with ``B`` the
baseline (m), ``d`` the subpixel disparity (px; SGBM returns 1/16 px steps) and ``doffs`` the
difference of the principal points ``c_x(right) - c_x(left)`` of a pre-rectified pair (px; 0
when rectified here; Middlebury's ``doffs``). The disparities searched follow from ``f_x``,
``B``, ``doffs`` and the depth range ``IngestParams.stereo_depth_range_m``.

Calibration file (``calibration.yaml``): YAML as OpenCV's FileStorage writes it
(``!!opencv-matrix`` nodes) or plain YAML lists (matrices as lists of rows).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from physanim.capture.frames import CaptureError
from physanim.capture.intrinsics import frame_rate, is_camera_matrix, pixel_count
from physanim.capture.params import IngestParams
from physanim.capture.subpixel import refine_disparity

CALIBRATION_KEYS = ("K1", "D1", "K2", "D2", "R", "T", "image_width", "image_height")
CALIBRATION_HELP = (
    "K1, K2 (3x3 px), D1, D2 (OpenCV distortion, 0, 4, 5, 8, 12 or 14 values), R (3x3), "
    "T (3 values, metres, x_right = R x_left + T), image_width, image_height (px), optional fps"
)
#: Largest plausible stereo baseline (m): larger values are taken for millimetres.
MAX_BASELINE_M = 2.0
MAX_DISPARITIES = 1024


def _cv_message(exc: cv2.error) -> str:
    """The gist of an OpenCV error, on one line: its message without the source location."""
    text = " ".join(line.lstrip("> ").strip() for line in str(exc).strip().splitlines())
    return re.sub(r"^.*?error: (\([^)]*\))?\s*", "", text).strip()[:200] or type(exc).__name__


class _CalibrationLoader(yaml.SafeLoader):
    """YAML loader that also reads OpenCV's ``!!opencv-matrix`` nodes (as mappings)."""


_CalibrationLoader.add_constructor(
    "tag:yaml.org,2002:opencv-matrix", lambda loader, node: loader.construct_mapping(node, True)
)


def _matrix(value: Any, key: str, shapes: tuple[tuple[int, ...], ...], path: Path) -> np.ndarray:
    """A calibration entry (OpenCV matrix mapping or nested lists) as an array of ``shapes``."""
    try:
        if isinstance(value, dict):
            arr = np.asarray(value["data"], dtype=np.float64)
            arr = arr.reshape(int(value["rows"]), int(value["cols"]))
        else:
            arr = np.asarray(value, dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise CaptureError(
            f"{path}: {key}: not a matrix ({exc}); write it as a list of rows, e.g. "
            "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]], or as an OpenCV !!opencv-matrix"
        ) from None
    for shape in shapes:
        vector = len(shape) == 1 and arr.size == shape[0] and np.squeeze(arr).ndim <= 1
        if vector or arr.shape == shape:
            out = arr.reshape(shape)
            if not np.isfinite(out).all():
                raise CaptureError(f"{path}: {key}: contains NaN or infinite values")
            return out
    want = " or ".join("x".join(map(str, s)) for s in shapes)
    raise CaptureError(f"{path}: {key}: expected {want} values, got shape {arr.shape}")


def _camera_matrix(value: Any, key: str, path: Path) -> np.ndarray:
    K = _matrix(value, key, ((3, 3),), path)
    if not is_camera_matrix(K):
        raise CaptureError(
            f"{path}: {key}: not a camera matrix (last row {K[2].tolist()}, expected [0, 0, 1]; "
            "fx, fy > 0); write it row by row: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
        )
    return K


@dataclass(frozen=True)
class StereoCalibration:
    """``K1``, ``K2`` (3, 3) px; ``D1``, ``D2`` OpenCV distortion; ``R`` (3, 3), ``T`` (3,) m
    map left-camera points to the right camera (x_r = R x_l + T); ``size`` (H, W) px."""

    K1: np.ndarray
    D1: np.ndarray
    K2: np.ndarray
    D2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    size: tuple[int, int]
    fps: float | None

    @classmethod
    def load(cls, path: Path) -> StereoCalibration:
        """Read and check ``path`` (see the module docstring); one-line errors name the key."""
        path = Path(path)
        if not path.is_file():
            raise CaptureError(
                f"{path}: missing stereo calibration; write a YAML file with {CALIBRATION_HELP}"
            )
        # PyYAML reads YAML 1.1 only: blank out OpenCV's "%YAML:1.0" / "%YAML 1.2" directive
        # (a blank line keeps the line numbers of parse errors right).
        text = re.sub(r"^%YAML.*$", "", path.read_text(errors="replace"), count=1, flags=re.M)
        try:
            data = yaml.load(text, Loader=_CalibrationLoader)  # a SafeLoader subclass
        except yaml.YAMLError as exc:
            where = getattr(exc, "problem_mark", None)
            at = f" at line {where.line + 1}, column {where.column + 1}" if where else ""
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise CaptureError(
                f"{path}: not valid YAML ({problem}{at}); fix the file: it needs {CALIBRATION_HELP}"
            ) from None
        if not isinstance(data, dict):
            raise CaptureError(f"{path}: expected a mapping of keys; it needs {CALIBRATION_HELP}")
        absent = [k for k in CALIBRATION_KEYS if data.get(k) is None]
        if absent:
            raise CaptureError(
                f"{path}: stereo calibration lacks {', '.join(absent)}; it needs {CALIBRATION_HELP}"
            )
        dist = ((0,), (4,), (5,), (8,), (12,), (14,))
        size = [pixel_count(data, k, path) for k in ("image_height", "image_width")]
        fps = frame_rate(data, "fps", None, path) if "fps" in data else None
        T = _matrix(data["T"], "T", ((3,),), path)
        R = _matrix(data["R"], "R", ((3, 3), (3,)), path)
        if R.shape == (3,):  # a rotation vector
            R = cv2.Rodrigues(R)[0]
        calib = cls(
            K1=_camera_matrix(data["K1"], "K1", path),
            D1=_matrix(data["D1"] or [], "D1", dist, path),
            K2=_camera_matrix(data["K2"], "K2", path),
            D2=_matrix(data["D2"] or [], "D2", dist, path),
            R=R,
            T=T,
            size=(size[0], size[1]),
            fps=fps,
        )
        if not np.allclose(calib.R @ calib.R.T, np.eye(3), atol=1e-4):
            raise CaptureError(f"{path}: R: not a rotation matrix (R R^T != I)")
        if np.linalg.det(calib.R) < 0:
            raise CaptureError(
                f"{path}: R: a reflection (determinant -1), not a rotation; give the rotation "
                "from the left to the right camera"
            )
        baseline = float(np.linalg.norm(T))
        if baseline > MAX_BASELINE_M:
            raise CaptureError(
                f"{path}: T: baseline {baseline:g} m is implausible; T is in metres (was it "
                f"given in millimetres? {baseline:g} mm = {baseline / 1000:g} m: write T in m)"
            )
        if baseline <= 0:
            raise CaptureError(f"{path}: T: zero baseline; T is the right camera's offset in m")
        return calib

    @property
    def doffs(self) -> float:
        """``c_x(right) - c_x(left)`` px of a pre-rectified pair (Middlebury's ``doffs``)."""
        return float(self.K2[0, 2] - self.K1[0, 2])

    def is_rectified(self) -> bool:
        """True if the pair is already row-aligned: no distortion, R = I, T along x, same
        focal lengths and principal-point row (the columns may differ: ``doffs``)."""
        return (
            not np.any(self.D1)
            and not np.any(self.D2)
            and np.allclose(self.R, np.eye(3), atol=1e-9)
            and np.allclose(self.T[1:], 0.0, atol=1e-9)
            and np.allclose(self.K1[[0, 1, 1], [0, 1, 2]], self.K2[[0, 1, 1], [0, 1, 2]])
            and self.K1[0, 1] == self.K2[0, 1] == 0
        )


def disparity_range(fx_b: float, doffs: float, depth_range_m: tuple[float, float]) -> range:
    """Integer disparities (px) SGBM must search for depths ``depth_range_m`` (near, far) m
    with ``fx_b`` = f_x * B (px m) and ``doffs`` px; its length is a multiple of 16."""
    near, far = depth_range_m
    lo = int(np.floor(fx_b / far - doffs))
    hi = int(np.ceil(fx_b / near - doffs))
    return range(lo, lo + 16 * max(1, -(-(hi - lo + 1) // 16)))


def sparse_disparities(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Disparities ``u_left - u_right`` (N,) px of cross-checked ORB matches between two
    rectified RGB images (H, W, 3) uint8 that lie on the same row (within 1.5 px)."""
    orb = cv2.ORB_create(nfeatures=2000)
    kl, dl = orb.detectAndCompute(cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), None)
    kr, dr = orb.detectAndCompute(cv2.cvtColor(right, cv2.COLOR_RGB2GRAY), None)
    if dl is None or dr is None:
        return np.zeros(0)
    matches = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(dl, dr)
    pl = np.array([kl[m.queryIdx].pt for m in matches]).reshape(-1, 2)
    pr = np.array([kr[m.trainIdx].pt for m in matches]).reshape(-1, 2)
    same_row = np.abs(pl[:, 1] - pr[:, 1]) <= 1.5
    return pl[same_row, 0] - pr[same_row, 0]


class StereoRig:
    """The rectified geometry of a calibrated pair: ``K`` (3, 3) px of the rectified left
    camera, ``baseline`` m, ``doffs`` px, ``size`` (H, W) px; ``rectified`` remaps a pair
    (identity when the calibration is already rectified)."""

    def __init__(self, calib: StereoCalibration) -> None:
        self.size = calib.size
        self.rectify = not calib.is_rectified()
        h, w = calib.size
        if self.rectify:
            r1, r2, p1, p2, *_ = cv2.stereoRectify(
                calib.K1,
                calib.D1,
                calib.K2,
                calib.D2,
                (w, h),
                calib.R,
                calib.T.reshape(3, 1),
                alpha=0,
            )
            self.maps = [
                cv2.initUndistortRectifyMap(k, d, r, p, (w, h), cv2.CV_32FC1)
                for k, d, r, p in ((calib.K1, calib.D1, r1, p1), (calib.K2, calib.D2, r2, p2))
            ]
            self.K = p1[:3, :3].copy()
            self.doffs = float(p2[0, 2] - p1[0, 2])
        else:
            self.K = calib.K1.copy()
            self.doffs = calib.doffs
        self.baseline = float(np.linalg.norm(calib.T))

    def rectified(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pair (H, W, 3) remapped to the rectified geometry (unchanged if pre-rectified)."""
        if not self.rectify:
            return left, right
        a, b = (
            cv2.remap(img, mx, my, cv2.INTER_LINEAR)
            for img, (mx, my) in zip((left, right), self.maps, strict=True)
        )
        return a, b


class StereoDepth(StereoRig):
    """SGBM stereo for one calibration; ``compute`` gives rectified left colour and depth.

    ``where`` (the calibration file) names the input in errors."""

    def __init__(self, calib: StereoCalibration, params: IngestParams, where: Path) -> None:
        try:
            super().__init__(calib)
        except cv2.error as exc:
            raise CaptureError(
                f"{where}: OpenCV cannot rectify this calibration ({_cv_message(exc)}); check "
                "K1, D1, K2, D2, R, T"
            ) from None
        self.params = params
        self.where = where
        w = self.size[1]
        self.disparities = disparity_range(
            self.K[0, 0] * self.baseline, self.doffs, params.stereo_depth_range_m
        )
        if len(self.disparities) > min(MAX_DISPARITIES, w // 2):
            near, far = params.stereo_depth_range_m
            raise CaptureError(
                f"{where}: ingest.stereo_depth_range_m [{near:g}, {far:g}] m needs disparities "
                f"{self.disparities.start}..{self.disparities.stop - 1} px with this calibration "
                f"(fx {self.K[0, 0]:.1f} px, baseline {self.baseline:g} m), more than "
                f"{min(MAX_DISPARITIES, w // 2)}; narrow the depth range"
            )
        bs = params.block_size
        self.left_matcher = cv2.StereoSGBM_create(
            minDisparity=self.disparities.start,
            numDisparities=len(self.disparities),
            blockSize=bs,
            P1=8 * 3 * bs * bs,
            P2=32 * 3 * bs * bs,
            disp12MaxDiff=-1,
            uniquenessRatio=params.uniqueness_ratio,
            speckleWindowSize=params.speckle_window_size,
            speckleRange=params.speckle_range,
            mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
        )
        self.right_matcher = cv2.ximgproc.createRightMatcher(self.left_matcher)

    def _texture(self, image: np.ndarray) -> np.ndarray:
        """Local grey-level std (H, W) over the SGBM block, 8-bit levels."""
        g = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)
        k = (self.params.block_size, self.params.block_size)
        mean = cv2.blur(g, k)
        return np.sqrt(np.maximum(cv2.blur(g * g, k) - mean * mean, 0.0))

    def disparity(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Left disparity (H, W) float32 px of rectified RGB images, NaN where invalid.

        Both images are padded on the left by the largest disparity (edge pixels repeated),
        so SGBM also matches the left image's first columns instead of leaving them
        invalid. Left-right check: a pixel is dropped where the right image's disparity at its
        match is valid and disagrees by more than ``lr_max_diff``; where the right matcher
        found nothing (its uniqueness and speckle filters) the left value is kept. Blocks
        with less grey-level texture than ``min_texture`` are dropped. The valid
        disparities are then refined to sub-pixel accuracy (``subpixel_sigma_px``,
        ``subpixel_iterations``; :func:`physanim.capture.subpixel.refine_disparity`).
        """
        p = self.params
        pad = max(self.disparities.stop, 0)
        left_p, right_p = (cv2.copyMakeBorder(im, 0, 0, pad, 0, cv2.BORDER_REPLICATE)
                           for im in (left, right))  # fmt: skip
        dl = self.left_matcher.compute(left_p, right_p)
        dr = self.right_matcher.compute(right_p, left_p)
        valid = dl[:, pad:] > (self.disparities.start - 1) * 16
        if p.wls:
            wls = cv2.ximgproc.createDisparityWLSFilter(self.left_matcher)
            wls.setLambda(p.wls_lambda)
            wls.setSigmaColor(p.wls_sigma)
            dl = wls.filter(dl, left_p, disparity_map_right=dr)
        disp = dl[:, pad:].astype(np.float32) / 16.0
        dr = dr[:, pad:]
        if p.min_texture > 0:
            valid &= self._texture(left) >= p.min_texture
        # d_l(x) ~ -d_r(x - d_l(x)) (the right matcher's disparities are negative).
        h, w = disp.shape
        cols = np.arange(w)[None, :] - np.rint(np.nan_to_num(disp)).astype(np.int64)
        inside = (cols >= 0) & (cols < w)
        back_raw = np.take_along_axis(dr, np.clip(cols, 0, w - 1), axis=1)
        right_valid = back_raw > -self.disparities.stop * 16
        consistent = ~right_valid | (np.abs(disp + back_raw / np.float32(16.0)) <= p.lr_max_diff)
        valid &= inside & consistent & (disp + self.doffs > 0)
        disp[~valid] = np.nan
        return refine_disparity(left, right, disp, p.subpixel_sigma_px, p.subpixel_iterations)

    def orientation(self, left: np.ndarray, right: np.ndarray) -> tuple[int, float, float]:
        """(number of sparse matches, fraction whose disparity is in the searched range, the
        same fraction if the images were swapped) for a rectified pair (H, W, 3)."""
        d = sparse_disparities(left, right)
        lo, hi = self.disparities.start, self.disparities.stop
        if not len(d):
            return 0, 0.0, 0.0
        return len(d), float(np.mean((d >= lo) & (d < hi))), float(np.mean((-d >= lo) & (-d < hi)))

    def at_limits(self, disp: np.ndarray) -> tuple[float, float]:
        """Fractions of the valid disparities (H, W) px within 1 px of the searched range's
        (far, near) ends: the scene probably extends beyond that end of the depth range."""
        d = disp[np.isfinite(disp)]
        if not len(d):
            return 0.0, 0.0
        lo, hi = self.disparities.start, self.disparities.stop - 1
        return float(np.mean(d <= lo + 1)), float(np.mean(d >= hi - 1))

    def depth(self, disp: np.ndarray) -> np.ndarray:
        """Depth (H, W) float32 m from disparity px (NaN stays NaN)."""
        return (self.K[0, 0] * self.baseline / (disp + self.doffs)).astype(np.float32)

    def compute(
        self, left: np.ndarray, right: np.ndarray, where: Path
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float]]:
        """(rectified left and right RGB (H, W, 3) uint8, depth (H, W) float32 m with NaN
        invalid, ``at_limits`` of the disparities)."""
        if left.shape[:2] != self.size:
            raise CaptureError(
                f"{where}: image is {left.shape[1]}x{left.shape[0]} but {self.where} gives "
                f"image_width {self.size[1]}, image_height {self.size[0]}; give image_width, "
                "image_height and K1, K2 of these images"
            )
        left, right = self.rectified(left, right)
        disp = self.disparity(left, right)
        return left, right, self.depth(disp), self.at_limits(disp)

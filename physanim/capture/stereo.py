"""Depth from a calibrated stereo pair: rectification, SGBM, left-right check, optional WLS.

Depth (m) along the rectified left camera's axis: ``z = f_x * B / d`` with ``B`` the
baseline (m) and ``d`` the subpixel disparity (px; SGBM returns 1/16 px steps).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from physanim.capture.frames import CaptureError
from physanim.capture.params import IngestParams

CALIBRATION_KEYS = ("K1", "D1", "K2", "D2", "R", "T", "image_width", "image_height")


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
        """Read an OpenCV FileStorage YAML with ``CALIBRATION_KEYS`` (+ optional ``fps``)."""
        if not path.is_file():
            raise CaptureError(
                f"{path}: missing stereo calibration; provide an OpenCV YAML with "
                f"{', '.join(CALIBRATION_KEYS)} (T in metres)"
            )
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        try:
            nodes = {k: fs.getNode(k) for k in (*CALIBRATION_KEYS, "fps")}
            absent = [k for k in CALIBRATION_KEYS if nodes[k].empty()]
            if absent:
                raise CaptureError(f"{path}: stereo calibration lacks {', '.join(absent)}")
            mats = {k: np.asarray(nodes[k].mat(), dtype=np.float64) for k in CALIBRATION_KEYS[:6]}
            size = (int(nodes["image_height"].real()), int(nodes["image_width"].real()))
            fps = None if nodes["fps"].empty() else float(nodes["fps"].real())
        finally:
            fs.release()
        mats["T"] = mats["T"].ravel()
        return cls(**mats, size=size, fps=fps)

    def is_rectified(self) -> bool:
        """True if the pair is already row-aligned: no distortion, R = I, T along x, K1 = K2."""
        return (
            not np.any(self.D1)
            and not np.any(self.D2)
            and np.allclose(self.R, np.eye(3), atol=1e-9)
            and np.allclose(self.T[1:], 0.0, atol=1e-9)
            and np.allclose(self.K1, self.K2)
        )


class StereoDepth:
    """SGBM stereo for one calibration; ``compute`` gives rectified left colour and depth."""

    def __init__(self, calib: StereoCalibration, params: IngestParams) -> None:
        self.size = calib.size
        self.params = params
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
        else:
            self.K = calib.K1.copy()
        self.baseline = float(np.linalg.norm(calib.T))
        bs = params.block_size
        self.left_matcher = cv2.StereoSGBM_create(
            minDisparity=params.min_disparity,
            numDisparities=params.num_disparities,
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
        """Left disparity (H, W) float32 px of rectified RGB images, NaN where invalid."""
        p = self.params
        dl = self.left_matcher.compute(left, right)
        dr = self.right_matcher.compute(right, left)
        invalid_raw = (p.min_disparity - 1) * 16
        valid = (dl > invalid_raw) & (self._texture(left) >= p.min_texture)
        if p.wls:
            wls = cv2.ximgproc.createDisparityWLSFilter(self.left_matcher)
            wls.setLambda(p.wls_lambda)
            wls.setSigmaColor(p.wls_sigma)
            dl = wls.filter(dl, left, disparity_map_right=dr)
        disp = dl.astype(np.float32) / 16.0
        # Left-right consistency: d_l(x) ~ -d_r(x - d_l(x)) (the right matcher is negative).
        h, w = disp.shape
        cols = np.arange(w)[None, :] - np.rint(np.nan_to_num(disp)).astype(np.int64)
        inside = (cols >= 0) & (cols < w)
        back = np.take_along_axis(dr.astype(np.float32) / 16.0, np.clip(cols, 0, w - 1), axis=1)
        valid &= inside & (np.abs(disp + back) <= p.lr_max_diff) & (disp > 0)
        disp[~valid] = np.nan
        return disp

    def compute(
        self, left: np.ndarray, right: np.ndarray, where: Path
    ) -> tuple[np.ndarray, np.ndarray]:
        """(rectified left RGB (H, W, 3) uint8, depth (H, W) float32 m, NaN invalid)."""
        if left.shape[:2] != self.size:
            raise CaptureError(
                f"{where}: image is {left.shape[1]}x{left.shape[0]} but the calibration says "
                f"{self.size[1]}x{self.size[0]}"
            )
        if self.rectify:
            left, right = (
                cv2.remap(img, mx, my, cv2.INTER_LINEAR)
                for img, (mx, my) in zip((left, right), self.maps, strict=True)
            )
        disp = self.disparity(left, right)
        depth = (self.K[0, 0] * self.baseline / disp).astype(np.float32)
        return left, depth

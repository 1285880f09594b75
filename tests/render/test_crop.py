"""The capture crop around the tracked landmarks (``physanim.render.crop``)."""

import numpy as np

from physanim.render.crop import face_crop


def test_crop_grows_the_landmark_box_with_the_tile_aspect_and_clips() -> None:
    uv = np.array([[[100.0, 200.0], [140.0, 260.0], [np.nan, np.nan]]])  # (T=1, K=3, 2) px
    # box 40 x 60 px; tile 120 x 160: height 60 > 40*160/120 -> half height 0.8 * 60 = 48
    assert face_crop(uv, (480, 640), (120, 160)) == (182, 278, 84, 156)
    assert face_crop(uv, (240, 130), (120, 160)) == (182, 240, 84, 130)  # clipped
    assert face_crop(np.full((2, 3, 2), np.nan), (480, 640), (120, 160)) == (0, 480, 0, 640)

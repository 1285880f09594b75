"""Side-by-side panels, landmark overlays and MP4 round trips."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import physanim.render.panel as panel_module
from physanim.render.panel import TITLE_HEIGHT, draw_landmarks, panel, write_mp4


def test_panel_size_and_titles():
    a = np.full((100, 80, 3), 30, np.uint8)
    b = np.full((50, 60, 3), 200, np.uint8)
    out = panel([a, b], ["capture", "FEM result"])
    # b is scaled to 100 rows -> 120 columns; title strip on top.
    assert out.shape == (TITLE_HEIGHT + 100, 80 + 120, 3)
    assert (out[TITLE_HEIGHT:, :80] == 30).all()
    assert np.abs(out[TITLE_HEIGHT + 2 : -2, 82:-2].astype(int) - 200).max() <= 1
    strip = out[:TITLE_HEIGHT]
    assert (strip[:, :80].sum(axis=2) < 300).sum() > 20  # dark title text in each tile
    assert (strip[:, 80:].sum(axis=2) < 300).sum() > 20


def test_panel_pads_to_even_size():
    out = panel([np.zeros((31, 33, 3), np.uint8)], ["x"])
    assert out.shape[0] % 2 == 0 and out.shape[1] % 2 == 0


def test_panel_rejects_mismatch():
    with pytest.raises(ValueError, match="one title per frame"):
        panel([np.zeros((4, 4, 3), np.uint8)], ["a", "b"])


def test_draw_landmarks_colours_by_confidence():
    img = np.zeros((60, 120, 3), np.uint8)
    uv = np.array([[20.0, 30.0], [60.0, 30.0], [np.nan, 5.0], [100.0, 30.0]])
    out = draw_landmarks(img, uv, np.array([1.0, 0.15, 1.0, 0.05]), min_confidence=0.1)
    assert (img == 0).all()  # input untouched
    ring_good = out[30, 20 + 4]  # on the ring of radius 4
    ring_bad = out[30, 60 + 4]
    assert ring_good[1] > 150 and ring_good[0] < 60  # green
    assert ring_bad[0] > 150 and ring_bad[1] < 60  # red
    assert (out[:, 90:] == 0).all()  # below min_confidence: skipped
    assert (out[:12] == 0).all()  # NaN: skipped


def test_write_mp4_round_trip(tmp_path):
    frames = [np.full((48, 64, 3), (10 * i, 100, 200 - 10 * i), np.uint8) for i in range(12)]
    path, codec = write_mp4(iter(frames), tmp_path / "v.mp4", fps=30.0)
    assert codec == "vp09"  # browser-playable codec available in OpenCV's FFmpeg here
    cap = cv2.VideoCapture(str(path))
    decoded = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        decoded.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    assert len(decoded) == 12
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(30.0)
    assert decoded[0].shape == (48, 64, 3)
    for src, got in zip(frames, decoded, strict=True):
        assert np.abs(got.astype(int) - src).mean() < 8


def test_write_mp4_errors(tmp_path):
    with pytest.raises(ValueError, match="suffix must be"):
        write_mp4([np.zeros((8, 8, 3), np.uint8)], tmp_path / "v.avi", 30.0)
    with pytest.raises(ValueError, match="no frames"):
        write_mp4([], tmp_path / "v.mp4", 30.0)
    frames = [np.zeros((8, 8, 3), np.uint8), np.zeros((8, 10, 3), np.uint8)]
    with pytest.raises(ValueError, match="frame 1 has shape"):
        write_mp4(frames, tmp_path / "v.mp4", 30.0)
    assert not list(tmp_path.iterdir())  # nothing half-written


def test_write_mp4_without_ffmpeg_falls_back_to_opencv(tmp_path, monkeypatch):
    # imageio-ffmpeg's FFmpeg (VP9 in realtime mode) is the fast path; OpenCV's VP9 remains
    monkeypatch.setattr(panel_module, "_ffmpeg_vp9", lambda *a: False)
    frames = [np.full((48, 64, 3), (10 * i, 100, 200 - 10 * i), np.uint8) for i in range(4)]
    path, codec = write_mp4(frames, tmp_path / "v.mp4", fps=30.0)
    assert codec == "vp09"
    monkeypatch.undo()
    _, codec = write_mp4(frames, tmp_path / "w.mp4", fps=30.0, ffmpeg=False)  # by choice
    assert codec == "vp09"
    for video in (path, tmp_path / "w.mp4"):  # both written by OpenCV: every frame decodes
        cap = cv2.VideoCapture(str(video))
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 4, video
        decoded = [cap.read()[1] for _ in range(4)]
        for src, got in zip(frames, decoded, strict=True):
            assert got is not None and got.shape == (48, 64, 3), video
            rgb = cv2.cvtColor(got, cv2.COLOR_BGR2RGB).astype(int)
            assert np.abs(rgb - src).mean() < 8, video  # the frame's own colour, not a blank


def test_write_webm_vp8(tmp_path):
    frames = [np.full((32, 48, 3), 17 * i, np.uint8) for i in range(5)]
    path, codec = write_mp4(frames, tmp_path / "v.webm", fps=25.0)
    assert codec == "VP80"
    cap = cv2.VideoCapture(str(path))
    n = 0
    while cap.read()[0]:
        n += 1
    assert n == 5


def test_panels_crop_the_face_and_write_every_frame(tmp_path):
    """The face panel's capture tile is the landmarks' box (+60 %, tile aspect) of every
    selected frame, read alike from numpy and Zarr; write_panels keeps one PNG per frame."""
    import zarr

    from physanim.render.face_panel import FaceFootage, capture_tiles, compose_panels, write_panels

    colour = np.zeros((4, 240, 320, 3), np.uint8)
    colour[:, 100:140, 150:170] = 255  # a white face where the landmarks are
    uv = np.tile([[150.0, 100.0], [170.0, 140.0]], (4, 1, 1))
    lazy = zarr.create_array(tmp_path / "c.zarr", shape=colour.shape, dtype="uint8")
    lazy[...] = colour
    tiles = {"fit": np.full((2, 160, 120, 3), 90, np.uint8)}
    frames = np.array([0, 2])
    panels = []
    for source in (colour, lazy):
        captured = capture_tiles(source, uv, np.ones((4, 2)), frames, (120, 160))
        footage = FaceFootage(captured, 10.0, {}, *[None] * 6, np.zeros((4, 1, 3)))
        panels.append(compose_panels(footage, frames, captured, tiles))
    assert len(panels[0]) == 2 and all((a == b).all() for a, b in zip(*panels, strict=True))
    # crop rows 88-152, cols 136-184 (half height 1.6 / 2 * 40 px, width 3/4 of it), scaled
    # to the tile's 160 rows: 120 columns, the white face in the middle, black beside it
    first = panels[0][0]
    assert first.shape == (TITLE_HEIGHT + 160, 120 + 120, 3)
    assert (first[TITLE_HEIGHT + 80, 60] == 255).all() and (first[TITLE_HEIGHT + 80, 5] == 0).all()
    video, _ = write_panels(panels[0], frames, tmp_path / "out", 5.0, png={0, 2})
    assert video.exists() and sorted(p.name for p in (tmp_path / "out" / "frames").iterdir()) == [
        "0000.png",
        "0002.png",
    ]

import cv2
import numpy as np

from physanim.dynamics.contact import Environment
from physanim.render.figure import render_animation
from tests.render.plot_content import assert_not_blank, capture_figures, curve_drawn, read_rgb


def test_render_animation_writes_frames_video_and_plot(arm2, tmp_path, monkeypatch):
    saved = capture_figures(monkeypatch)
    q = np.array([[0.0, 0.0], [0.5, 0.3], [1.0, 0.6]])
    base = np.array([[0.0, 1.0, 0.0]] * 3)
    env = Environment(boxes=[(np.array([-0.3, 0.0, -0.3]), np.array([0.3, 0.2, 0.3]))])
    out = render_animation(
        arm2, q, base, 30.0, tmp_path, env=env, trail_links=["elbow"], title="arm2"
    )
    frames = sorted(out["frames"].glob("frame_*.png"))
    assert len(frames) == 3
    img0, img2 = cv2.imread(str(frames[0])), cv2.imread(str(frames[2]))
    assert img0.shape == (480, 640, 3) and np.abs(img0.astype(int) - img2).sum() > 0
    cap = cv2.VideoCapture(str(out["video"]))
    assert cap.isOpened() and int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    # the joint-angle plot: each joint's angle (deg) over time (s), shoulder C0, elbow C1
    img = read_rgb(out["plot"])
    assert_not_blank(img)
    fig = next(f for f, p in saved if p.name == out["plot"].name)
    t = np.linspace(0.0, 2 / 30, 41)
    for j, colour in enumerate(("C0", "C1")):
        deg = np.degrees(np.interp(t, np.arange(3) / 30, q[:, j]))
        assert curve_drawn(img, fig, fig.axes[0], t, deg, colour) > 0.95, colour
    # swapped, the curves are not where the other joint's angles would put them
    assert (
        curve_drawn(img, fig, fig.axes[0], t, np.degrees(np.interp(t, [0, 2 / 30], [0, 0.6])), "C0")
        < 0.5
    )

from pathlib import Path

import numpy as np
import pytest

from physanim.dynamics import capsule_segments, forward_kinematics
from physanim.dynamics.contact import capsule_box_distance, capsule_plane_distance
from physanim.dynamics.interpolation import evaluate, hermite, quadratic
from physanim.dynamics.keyframes import KeyframeSpec, animate_joints, run_keyframes
from physanim.spline import natural_spline

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

FPS = 30.0


@pytest.fixture(scope="module")
def jump(human):
    spec = KeyframeSpec.from_yaml(CONFIGS / "keyframes" / "jump.yaml")
    return spec, run_keyframes(human, spec)


@pytest.fixture(scope="module")
def throw(human):
    spec = KeyframeSpec.from_yaml(CONFIGS / "keyframes" / "throw.yaml")
    return spec, run_keyframes(human, spec)


def test_interpolants_hit_their_end_conditions():
    a, va, b, vb, h = np.array([0.2]), np.array([1.5]), np.array([-0.4]), np.array([0.3]), 0.4
    th, v, _ = evaluate(hermite(a, va, b, vb, h), np.array([0.0, h]))
    np.testing.assert_allclose(th[:, 0], [a[0], b[0]])
    np.testing.assert_allclose(v[:, 0], [va[0], vb[0]])
    th, v, acc = evaluate(quadratic(a, va, b, h), np.array([0.0, h]))
    np.testing.assert_allclose(th[:, 0], [a[0], b[0]])
    assert v[0, 0] == pytest.approx(va[0]) and acc[0, 0] == pytest.approx(acc[1, 0])


def test_capsule_distances_against_brute_force():
    rng = np.random.default_rng(0)
    lo, hi = np.array([-0.5, 0.0, -0.3]), np.array([0.5, 0.25, 0.4])
    a, b = rng.uniform(-1, 1, (50, 3)), rng.uniform(-1, 1, (50, 3))
    r = rng.uniform(0.01, 0.1, 50)
    d, _ = capsule_box_distance(a, b, r, lo, hi)
    s = np.linspace(0, 1, 20001)[:, None, None]
    p = a + s * (b - a)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    e = np.abs(p - centre) - half
    sd = np.linalg.norm(np.maximum(e, 0), axis=-1) + np.minimum(e.max(-1), 0)
    brute = sd.min(0) - r  # sampled every ~1e-4 m: within 2e-4 m of the true minimum
    assert (d <= brute + 1e-12).all()
    np.testing.assert_allclose(d, brute, atol=2e-4)
    dp, _ = capsule_plane_distance(a, b, r, 0.1, np.array([0.0, 1.0, 0.0]))
    np.testing.assert_allclose(dp, np.minimum(a[:, 1], b[:, 1]) - 0.1 - r)


def test_throw_keys_simulation_and_pin(human, throw):
    spec, res = throw
    assert res.q.shape == (31, 30)
    arms = human.subtree("r_shoulder_x") | human.subtree("l_shoulder_x")
    np.testing.assert_array_equal(res.simulated[6:16].any(0), arms)  # frames 6..15
    assert not res.simulated[:6].any() and not res.simulated[16:].any()
    assert (res.q >= human.lower - 1e-9).all() and (res.q <= human.upper + 1e-9).all()
    # keys are met by interpolated joints; the arms at K3 come from the dynamics
    lumbar = human.index("lumbar_y")
    for key in spec.keys:
        assert res.q[key.frame, lumbar] == pytest.approx(np.radians(key.angles["lumbar_y"]))
    r_el = human.index("r_shoulder_x")
    assert res.q[30, r_el] == pytest.approx(np.radians(20.0))
    # passive swing reacts to the launch velocity: shoulder keeps moving forward after K2
    assert res.q[8, r_el] > res.q[5, r_el]
    # the left ankle stays where it started
    kin = forward_kinematics(human, res.q, base_pos=res.placement.base_pos)
    ankle = kin.positions[:, human.index("l_ankle_x")]
    np.testing.assert_allclose(ankle, np.broadcast_to([0.09, 0.05, 0.0], ankle.shape), atol=1e-12)


def test_simulated_interval_independent_of_inertia_method(human):
    spec = KeyframeSpec.from_yaml(CONFIGS / "keyframes" / "throw.yaml")
    q1, _, _ = animate_joints(human, spec, substeps=2, method="crba")
    q2, _, _ = animate_joints(human, spec, substeps=2, method="rnea")
    np.testing.assert_allclose(q1, q2, atol=1e-9)


def test_jump_contact_and_ballistic_flight(human, jump):
    spec, res = jump
    p = res.placement
    assert p.distance.min() > -1e-3  # no penetration over 1 mm
    kin = forward_kinematics(human, res.q, base_pos=p.base_pos)
    a, b = capsule_segments(human, kin)
    solid = human.radius > 0
    low = np.minimum(a[..., 1], b[..., 1])[:, solid] - human.radius[solid]
    assert low.min() > -1e-3
    free = ~p.contact
    takeoff = int(np.argmax(free)) - 1  # last frame on the platform
    landing = takeoff + 1 + int(np.argmax(p.contact[takeoff + 1 :]))
    assert 4 <= takeoff <= 8 and 15 <= landing <= 22  # seed: leaves at F6, lands at F18
    assert free[takeoff + 1 : landing].all()
    # COM follows a parabola with gravity in flight: second differences = g dt^2
    dd = np.diff(p.com[takeoff:landing], 2, axis=0)
    np.testing.assert_allclose(dd, np.broadcast_to([0, -9.81 / FPS**2, 0], dd.shape), atol=1e-9)
    # flight time equals the ballistic time from the take-off velocity within one frame
    v0 = (p.com[takeoff] - p.com[takeoff - 1]) * FPS
    y0, y1, g = p.com[takeoff, 1], p.com[landing, 1], 9.81
    t_fall = (v0[1] + np.sqrt(v0[1] ** 2 + 2 * g * (y0 - y1))) / g
    assert abs(t_fall * FPS - (landing - takeoff)) <= 1.0
    # the landing is on the ground, in front of the platform; the right ankle then stays put
    ankle = kin.positions[:, human.index("r_ankle_x")]
    assert ankle[landing, 2] > 0.0 and p.pinned[landing] == human.index("r_ankle_x")
    np.testing.assert_allclose(
        ankle[landing:, [0, 2]],
        ankle[landing, [0, 2]][None].repeat(len(ankle) - landing, 0),
        atol=1e-9,
    )


def test_keyframe_file_errors(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("figure: x.yaml\nkeys: [{frame: 5}, {frame: 3}]\n")
    with pytest.raises(ValueError, match="frames must increase"):
        KeyframeSpec.from_yaml(bad)
    with pytest.raises(FileNotFoundError):
        KeyframeSpec.from_yaml(tmp_path / "missing.yaml")


@pytest.fixture(scope="module")
def walk_spec():
    return KeyframeSpec.from_yaml(CONFIGS / "keyframes" / "walk.yaml")


def _with_path(spec, **changes):
    return spec.model_copy(update={"path": spec.path.model_copy(update=changes)})


@pytest.mark.parametrize("spacing", ["uniform", "arc", "curvature", "ease"])
def test_root_path_follows_the_spline_by_its_spacing_rule(human, walk_spec, spacing):
    rule = 0.5 - 0.5 * np.cos(np.linspace(0, 2 * np.pi, 49)[1:]) if spacing == "ease" else spacing
    spec = _with_path(walk_spec, spacing=rule if isinstance(rule, str) else list(rule))
    spec = _with_path(spec, on_ground=False)
    res = run_keyframes(human, spec)
    points = np.array(spec.path.points)
    base = res.placement.base_pos
    np.testing.assert_array_equal(base[0], points[0])
    np.testing.assert_allclose(base[-1], points[-1], atol=1e-12)  # no drift at the end
    sp = natural_spline(points, extra_point="reflect")
    s = sp.arc_length(_params_of(sp, base))
    steps = np.diff(s)
    if spacing == "arc":
        np.testing.assert_allclose(steps, sp.length / 48, rtol=1e-9)
    elif spacing == "uniform":
        np.testing.assert_allclose(np.diff(_params_of(sp, base)), sp.t_end / 48, rtol=1e-9)
    elif spacing == "curvature":
        q = sp.curvature(_params_of(sp, base))
        np.testing.assert_allclose(np.diff(q), q[-1] / 48, rtol=1e-8)
    else:
        np.testing.assert_allclose(steps / sp.length, rule / rule.sum(), atol=1e-9)


def _params_of(sp, base):
    """Spline parameters of points on the path (nearest of a fine grid, then Newton)."""
    grid = np.linspace(0, sp.t_end, 20001)
    t = grid[np.argmin(np.linalg.norm(sp(grid)[None] - base[:, None], axis=-1), axis=1)]
    for _ in range(20):
        d, v, a = sp(t) - base, sp(t, 1), sp(t, 2)
        t = t - np.einsum("ij,ij->i", d, v) / (
            np.einsum("ij,ij->i", v, v) + np.einsum("ij,ij->i", d, a)
        )
    np.testing.assert_allclose(sp(t), base, atol=1e-12)
    return t


def test_walk_turns_along_the_path_and_keeps_a_foot_on_the_ground(human, walk_spec):
    res = run_keyframes(human, walk_spec)
    p = res.placement
    np.testing.assert_allclose(p.distance, 0.0, atol=1e-12)  # the lowest capsule touches
    np.testing.assert_allclose(p.base_pos[-1, [0, 2]], walk_spec.path.points[-1][::2], atol=1e-12)
    # the pelvis faces along the path: its +z axis is the path's horizontal tangent
    kin = forward_kinematics(human, res.q, base_pos=p.base_pos)
    facing = kin.rotations[:, human.index("pelvis_z")] @ np.array([0.0, 0.0, 1.0])
    sp = natural_spline(np.array(walk_spec.path.points), extra_point="reflect")
    tangent = sp(_params_of(sp, p.base_pos * [1, 0, 1]), 1)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    np.testing.assert_allclose(facing, tangent, atol=1e-9)
    # heading rate: the joint velocity includes the turn
    j = human.index("pelvis_y")
    np.testing.assert_allclose(res.qd[1:-1, j], np.gradient(res.q[:, j], 1 / 30)[1:-1], atol=0.05)
    speed = np.linalg.norm(np.diff(p.base_pos[:, [0, 2]], axis=0), axis=1) * 30
    assert 1.0 < speed.min() and speed.max() / speed.min() < 1.01  # about 1.1 m/s, constant


def test_root_path_errors(walk_spec, tmp_path):
    with pytest.raises(ValueError, match="path.spacing: give 48"):
        KeyframeSpec.model_validate(
            {
                **walk_spec.model_dump(),
                "path": {**walk_spec.path.model_dump(), "spacing": [1.0, 2.0]},
            }
        )
    bad = {
        **walk_spec.model_dump(),
        "world": {
            "constraints": [{"type": "pin", "joint": "r_ankle_x", "from_key": 4, "to_key": 6}]
        },
    }
    with pytest.raises(ValueError, match=r"constraints\[0\] \(frames 32..48\) overlaps the path"):
        KeyframeSpec.model_validate(bad)
    with pytest.raises(ValueError, match="from_key < to_key"):
        KeyframeSpec.model_validate(
            {**walk_spec.model_dump(), "path": {**walk_spec.path.model_dump(), "from_key": 6}}
        )

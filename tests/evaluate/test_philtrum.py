"""The philtrum curves: each free node of a region weighed by its share of the region's
volume, so the figure is the region's mean and not the mesh's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from physanim.evaluate.face import philtrum_curves


def test_nodes_weigh_by_their_share_of_the_region_volume() -> None:
    # two tets of the right philtrum sharing the face 0-1-2: one of volume 1/6 and one of 3/6
    # (apex 4 at z = -3)
    nodes = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -3], [5, 5, 5]], float)
    tets = np.array([[0, 1, 2, 3], [4, 2, 1, 0], [1, 2, 3, 5]])
    labels = np.array([0, 0, 1])  # the third tet is the left philtrum's
    moved = np.array([0.0, 1.0, 1.0, 1.0, 4.0, 9.0])  # node displacement along x, m
    disp = np.zeros((2, len(nodes), 3))
    disp[1, :, 0] = moved
    run = SimpleNamespace(
        displacements=disp, nodes=nodes, tets=tets, tet_labels=labels,
        region_names=["cphs_R", "cphs_L"], driven=np.array([5]),
    )  # fmt: skip
    curves = philtrum_curves(run)  # a FaceRun's fields that the curves read
    # volumes 1/6 and 3/6: node 0 gets (1 + 3) / 24, nodes 1, 2 the same, 3 gets 1/24, 4 3/24
    w = np.array([4, 4, 4, 1, 3]) / 24
    np.testing.assert_allclose(curves["right"], [0.0, w @ moved[:5] / w.sum()])
    # 21/16: the plain node mean would read (0 + 1 + 1 + 1 + 4) / 5 = 1.4
    assert curves["right"][1] < 1.4
    # the left philtrum's only tet has the driven node 5: its free nodes 1, 2, 3 weigh equally
    np.testing.assert_allclose(curves["left"], [0.0, 1.0])

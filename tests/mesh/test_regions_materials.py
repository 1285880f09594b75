"""Facial material regions (symmetry, volume propagation) and per-tet materials files."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from matplotlib import pyplot as plt
from pydantic import ValidationError

from physanim.fem.region_materials import material_table, tet_materials
from physanim.mesh.params import REGION_NAMES, MaterialModel, MaterialsParams
from physanim.mesh.regions import (
    DEFAULT_LABEL,
    LABEL_NAMES,
    plot_regions,
    region_areas,
    skin_regions,
    tet_regions,
)
from tests.render.plot_content import assert_not_blank, capture_figures, read_rgb

MATERIALS_DIR = Path(__file__).resolve().parents[2] / "configs" / "materials"


def side_areas(v, f, labels):
    """Area (m^2) per region label on the actor's left (x > 0) and right (x < 0) sides."""
    left = region_areas(v, f, np.where(v[:, 0] > 0, labels, DEFAULT_LABEL))
    right = region_areas(v, f, np.where(v[:, 0] < 0, labels, DEFAULT_LABEL))
    return left, right


def test_regions_cover_the_face_symmetrically(skin, landmarks, tmp_path, monkeypatch):
    saved = capture_figures(monkeypatch)
    v, f = skin
    labels = skin_regions(v, landmarks, MaterialsParams())
    left, right = side_areas(v, f, labels)
    for name in ("Cheek", "Cheilion", "cphi", "Alare"):
        i = LABEL_NAMES.index(name)
        assert left[i] > 0 and abs(left[i] - right[i]) <= 0.1 * max(left[i], right[i]), name
    # cphs: the L region lies on the left, the R region is its mirror image.
    total = region_areas(v, f, labels)
    cl, cr = total[LABEL_NAMES.index("cphs_L")], total[LABEL_NAMES.index("cphs_R")]
    assert cl > 0 and abs(cl - cr) <= 0.1 * max(cl, cr)
    assert np.all(v[labels == LABEL_NAMES.index("cphs_L"), 0] > -0.005)
    # Every region is present, and most of the face stays default.
    assert np.all(total > 0) and total[DEFAULT_LABEL] > 0.5 * total.sum()
    png = plot_regions(v, f, labels, tmp_path / "regions.png", landmarks)
    _check_region_plot(png, saved[-1][0])


def _check_region_plot(png, fig):
    """Every region's colour is painted on the face (the legend left out), whatever its
    shading (chromaticity r : g : b), and cphs_L on the viewer's right of x = 0, cphs_R left."""
    img = read_rgb(png).astype(float)
    assert_not_blank(img)
    # pixels of the PNG (saved with bbox_inches="tight", pad 0.1 in) from display coordinates
    tight = fig.get_tightbbox()
    x0, top = (tight.x0 - 0.1) * fig.dpi, (tight.y1 + 0.1) * fig.dpi
    ax = fig.axes[0]
    leg = ax.get_legend().get_window_extent()
    on_face = np.ones(img.shape[:2], bool)
    on_face[
        int(top - leg.y1) - 2 : int(top - leg.y0) + 3, int(leg.x0 - x0) - 2 : int(leg.x1 - x0) + 3
    ] = False
    bright = img.sum(axis=2) > 120  # not the black landmark dots and labels
    chroma = img / np.maximum(img.sum(axis=2, keepdims=True), 1.0)
    centre = ax.transData.transform([[0.0, 0.0]])[0, 0] - x0  # column of x = 0
    cmap = plt.get_cmap("tab10")
    where = {}
    for i, name in enumerate(LABEL_NAMES[1:], start=1):
        rgb = np.array(cmap(i)[:3])
        near = np.linalg.norm(chroma - rgb / rgb.sum(), axis=2) < 0.03
        where[name] = np.nonzero(near & bright & on_face)[1]
        assert len(where[name]) > 20, (name, len(where[name]))
        assert np.any(near & bright & ~on_face), name  # and it has a legend entry
    assert np.mean(where["cphs_L"] > centre) > 0.95 and np.mean(where["cphs_R"] < centre) > 0.95


def test_tet_regions_take_the_nearest_skin_label():
    skin_pts = np.array([[0.0, 0, 0], [0.1, 0, 0]])
    nodes = np.array(
        [
            [0.0, 0, -0.01],
            [0.01, 0, -0.02],
            [0, 0.01, -0.02],
            [0, 0, -0.03],
            [0.1, 0, -0.01],
            [0.11, 0, -0.02],
            [0.1, 0.01, -0.02],
            [0.1, 0, -0.03],
        ]
    )
    tets = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    np.testing.assert_array_equal(tet_regions(nodes, tets, skin_pts, np.array([3, 5])), [3, 5])


@pytest.mark.parametrize("name", ["uniform", "model1", "model2", "model3"])
def test_shipped_materials_files_are_valid(name):
    model = MaterialModel.model_validate(
        yaml.safe_load((MATERIALS_DIR / f"{name}.yaml").read_text())["materials"]["model"]
    )
    table = material_table(model)
    assert table.shape == (1 + len(REGION_NAMES), 4)
    np.testing.assert_allclose(table[0], [192.4e3, 0.495, 476.8, 1100.0])  # seed uniform values
    np.testing.assert_allclose(table[:, 1], 0.495)
    np.testing.assert_allclose(table[:, 3], 1100.0)


def test_seed_model_values_per_tet():
    load = lambda n: MaterialModel.model_validate(  # noqa: E731
        yaml.safe_load((MATERIALS_DIR / f"{n}.yaml").read_text())["materials"]["model"]
    )
    labels = np.arange(1 + len(REGION_NAMES))  # default, Cheek, cphs_L, cphs_R, ...
    m1, m2, m3 = (tet_materials(labels, load(n)) for n in ("model1", "model2", "model3"))
    np.testing.assert_allclose(m1.E[1:], np.array([162.7, 148.9, 148.9, 116.5, 169.0, 216.9]) * 1e3)
    np.testing.assert_allclose(m1.eta[1:], [430.3, 408.6, 408.6, 362.9, 453.0, 434.3])
    cphs_r = 1 + REGION_NAMES.index("cphs_R")
    assert (m2.E[cphs_r], m2.eta[cphs_r]) == (205.6e3, 427.8)
    assert (m3.E[cphs_r], m3.eta[cphs_r]) == (92.2e3, 389.4)
    others = np.arange(len(labels)) != cphs_r
    np.testing.assert_array_equal(m2.E[others], m1.E[others])


def test_bad_materials_are_rejected_with_the_field_named():
    base = {"name": "x", "default": {"E_kPa": 1.0, "nu": 0.3, "eta_Pa_s": 1.0, "rho_kg_m3": 1e3}}
    with pytest.raises(ValidationError, match="unknown region"):
        MaterialModel.model_validate({**base, "regions": {"Chin": base["default"]}})
    with pytest.raises(ValidationError, match="nu"):
        MaterialModel.model_validate({**base, "default": {**base["default"], "nu": 0.5}})
    with pytest.raises(ValueError, match="tet_labels"):
        tet_materials(np.array([9]), MaterialModel.model_validate(base))

"""The actuation drive's gesture factors (DriveParams.actuation_scale) and the inverse step's
regional stress costs (ActuationParams.region_stress_cost_mm_per_kPa)."""

import pytest
from pydantic import ValidationError

from physanim.face.params import FACE_REGIONS, ActuationParams, DriveParams


def test_a_regions_own_factor_wins_over_the_whole_faces() -> None:
    drive = DriveParams(mode="actuation", actuation_scale={"face": 1.2, "mouth": 1.5})
    assert drive.scale_of("mouth") == 1.5
    assert drive.scale_of("cheeks") == 1.2 and drive.scale_of(None) == 1.2
    assert DriveParams().scale_of("nose") == 1.0


@pytest.mark.parametrize("scale", [{"lips": 1.5}, {"mouth": -0.5}])
def test_unknown_regions_and_negative_factors_are_refused(scale) -> None:
    with pytest.raises(ValidationError, match="unknown region|>= 0"):
        DriveParams(actuation_scale=scale)
    assert "mouth" in FACE_REGIONS


def test_a_patch_costs_its_regions_own_or_the_deep_tissues_where_larger() -> None:
    """Cost factors against the default stress cost: a region's own cost (looser or stiffer),
    the deep tissue's where the patch lies deeper and that is larger, else 1."""
    fit = ActuationParams(
        stress_cost_mm_per_kPa=0.001,
        region_stress_cost_mm_per_kPa={"mouth": 0.004, "forehead": 0.0005, "deep": 0.002},
        deep_below_m=0.01,
    )
    regions = ["mouth", "mouth", "forehead", "forehead", "cheeks", "cheeks", None]
    depths = [0.002, 0.02, 0.002, 0.02, 0.002, 0.02, 0.02]
    assert fit.patch_cost(regions, depths) == pytest.approx([4, 4, 0.5, 2, 1, 2, 2])
    plain = ActuationParams(region_stress_cost_mm_per_kPa={})
    assert plain.patch_cost(regions, depths) == [1.0] * len(regions)


@pytest.mark.parametrize("costs", [{"lips": 0.001}, {"mouth": 0.0}, {"deep": 20.0}])
def test_unknown_regions_and_costs_out_of_range_are_refused(costs) -> None:
    with pytest.raises(ValidationError, match="unknown region|costs must be"):
        ActuationParams(region_stress_cost_mm_per_kPa=costs)

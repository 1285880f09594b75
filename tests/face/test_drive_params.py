"""The actuation drive's gesture factors (DriveParams.actuation_scale)."""

import pytest
from pydantic import ValidationError

from physanim.face.params import FACE_REGIONS, DriveParams


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

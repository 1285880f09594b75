"""Stage outputs as dataclasses: what ``write_dataclass`` stores and ``read_dataclass`` rebuilds."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
import zarr

from physanim.store import read_dataclass, write_dataclass


@dataclass(frozen=True)
class Pose:
    angle: np.ndarray  # (T,) rad


@dataclass(frozen=True)
class Output:
    frames: np.ndarray = field(metadata={"lazy": True})  # (T, 4) m
    names: list[str] = field(metadata={"stored": "labels"})
    pose: Pose
    optional: Pose | None
    fps: float = 30.0


@dataclass(frozen=True)
class Conditions:
    by_name: dict[str, Pose] = field(metadata={"stored": ""})


def test_round_trip_nested_lazy_renamed_and_optional(tmp_path) -> None:
    group = zarr.open_group(tmp_path / "g", mode="w")
    frames = np.arange(12.0).reshape(3, 4)
    write_dataclass(group, Output(frames, ["a", "b"], Pose(np.array([0.1, 0.2])), None))
    assert group.attrs["labels"] == ["a", "b"] and group.attrs["optional"] is None
    assert "pose/angle" in group and group["frames"].chunks[0] >= 1
    back = read_dataclass(Output, group)
    assert isinstance(back.frames, zarr.Array) and back.frames[1, 2] == 6.0  # read on demand
    assert back.names == ["a", "b"] and back.optional is None and back.fps == 30.0
    np.testing.assert_array_equal(back.pose.angle, [0.1, 0.2])


def test_dict_of_dataclasses_one_group_per_key_and_missing_field_named(tmp_path) -> None:
    group = zarr.open_group(tmp_path / "g", mode="w")
    write_dataclass(group, Conditions({"free": Pose(np.zeros(2)), "load": Pose(np.ones(2))}))
    assert sorted(group.group_keys()) == ["free", "load"]
    back = read_dataclass(Conditions, group)
    np.testing.assert_array_equal(back.by_name["load"].angle, [1.0, 1.0])
    with pytest.raises(KeyError, match=r"g/: no 'frames' \(Output.frames\)"):
        read_dataclass(Output, group)

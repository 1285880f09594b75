"""What a stage's compute function sees: its params, its inputs and the group it writes to."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Generic, TypeVar

import numpy as np
import zarr
from pydantic import BaseModel

from physanim.pipeline.spec import DatasetParams, StageSpec
from physanim.store import StageStore, read_dataclass, write_array, write_dataclass

P = TypeVar("P", bound=BaseModel)
T = TypeVar("T")
M = TypeVar("M", bound=BaseModel)

#: progress callback passed to library loops: (done, total) -> None
ProgressFn = Callable[[int, int], None]
ProgressFactory = Callable[[str], ProgressFn]


def _no_progress(_description: str) -> ProgressFn:
    return lambda done, total: None


@dataclass
class StageContext(Generic[P]):
    """Inputs and outputs of one stage execution.

    ``out`` is the (temporary) Zarr group of this output; it becomes visible to readers only
    after ``compute`` returns.  ``config`` is the whole validated config (read-only), for the
    rare stage that needs another section (e.g. dataset paths).
    """

    spec: StageSpec[P]
    params: P
    key: str
    upstream: Mapping[str, str]
    store: StageStore
    dataset: DatasetParams
    out: zarr.Group
    progress: ProgressFactory = field(default=_no_progress)

    def input(self, stage: str) -> zarr.Group:
        """The output group of upstream ``stage`` (read-only)."""
        if stage not in self.upstream:
            raise KeyError(f"stage {self.spec.name} does not declare {stage!r} as upstream")
        return self.store.open(stage, self.upstream[stage])

    def read(self, stage: str, output: type[T]) -> T:
        """The output of upstream ``stage`` as its dataclass ``output`` (typed stages)."""
        return read_dataclass(output, self.input(stage))

    def upstream_params(self, stage: str, model: type[M]) -> M:
        """The params upstream ``stage`` ran with, as its params ``model``."""
        if stage not in self.upstream:
            raise KeyError(f"stage {self.spec.name} does not declare {stage!r} as upstream")
        return model.model_validate(self.store.provenance(stage, self.upstream[stage])["params"])

    def write(self, name: str, data: np.ndarray) -> zarr.Array:
        """Write one array of this output, chunked by frames."""
        return write_array(self.out, name, data)

    @property
    def files_dir(self) -> Path:
        """Directory for this output's plain files (PNG, MP4, HTML), committed with the arrays."""
        d = Path(self.out.store.root) / self.out.path / "files"
        d.mkdir(parents=True, exist_ok=True)
        return d

    def write_record(self, record: object, prefix: str = "") -> None:
        """Write every array field of a dataclass (``prefix/<field>``), chunked by frames."""
        write_dataclass(self.out, record, prefix)

    @property
    def dataset_dir(self) -> Path:
        """The dataset directory."""
        return self.dataset.path

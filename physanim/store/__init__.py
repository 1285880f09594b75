"""Content-addressed Zarr store of stage outputs (see stage_store for the layout)."""

from physanim.store.keys import canonical_json, files_fingerprint, stage_key
from physanim.store.stage_store import (
    RunRecord,
    StageOutputDamaged,
    StageOutputMissing,
    StageStore,
    frame_chunks,
    read_dataclass,
    write_array,
    write_dataclass,
)

__all__ = [
    "RunRecord",
    "StageOutputDamaged",
    "StageOutputMissing",
    "StageStore",
    "canonical_json",
    "files_fingerprint",
    "frame_chunks",
    "read_dataclass",
    "stage_key",
    "write_array",
    "write_dataclass",
]

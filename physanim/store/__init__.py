"""Content-addressed Zarr store of stage outputs (see stage_store for the layout)."""

from physanim.store.codec import frame_chunks, read_dataclass, write_array, write_dataclass
from physanim.store.keys import canonical_json, files_fingerprint, stage_key
from physanim.store.runs import RunRecord
from physanim.store.stage_store import StageOutputDamaged, StageOutputMissing, StageStore

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

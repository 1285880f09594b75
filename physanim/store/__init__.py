"""Content-addressed Zarr store of stage outputs (see stage_store for the layout)."""

from physanim.store.keys import canonical_json, stage_key
from physanim.store.stage_store import StageOutputMissing, StageStore, frame_chunks, write_array

__all__ = [
    "StageOutputMissing",
    "StageStore",
    "canonical_json",
    "frame_chunks",
    "stage_key",
    "write_array",
]

"""The export's file cache: an unchanged animation's files come back as the same files on disk
(hard links: a material edit's variants do not each hold a copy of the capture's), with the
same fidelity figures; a changed one is written anew."""

from __future__ import annotations

from pathlib import Path

from physanim.export.animation import MeshAnimation
from physanim.export.files import cached_export_files
from physanim.export.params import ExportParams
from physanim.store.file_cache import FileCache
from tests.export.conftest import three_modes


def test_an_unchanged_animation_is_shared_and_a_changed_one_written(tmp_path: Path) -> None:
    cache, params = FileCache(tmp_path / "cache"), ExportParams()
    anim = three_modes()
    first, again, moved = (tmp_path / n for n in ("first", "again", "moved"))
    for folder in (first, again, moved):
        folder.mkdir()
    made = cached_export_files(anim, first, params, "a doc", cache)
    assert len(list((tmp_path / "cache").iterdir())) == 3  # usdc, glb and the figures
    copied = cached_export_files(anim, again, params, "a doc", cache)
    assert [p.name for p in copied.paths] == [p.name for p in made.paths]
    for a, b in zip(made.paths, copied.paths, strict=True):
        assert a.read_bytes() == b.read_bytes() and b.parent == again
        assert a.samefile(b) and a.stat().st_nlink == 3  # the first, the cache's, this one
    assert (copied.targets, copied.rms_mm, copied.max_mm) == (
        made.targets,
        made.rms_mm,
        made.max_mm,
    )
    shifted = MeshAnimation(anim.name, anim.points * 1.01, anim.faces, anim.fps)
    other = cached_export_files(shifted, moved, params, "a doc", cache)
    assert other.usd.read_bytes() != made.usd.read_bytes()
    assert other.rms_mm != made.rms_mm or other.max_mm != made.max_mm

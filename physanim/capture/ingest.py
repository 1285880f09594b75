"""Capture ingest: read a RealSense bag, an Open3D RGBD folder or a stereo pair into a
``Capture`` (colour, metric depth, intrinsics, timestamps, validity statistics).

``load_capture`` picks the source named by ``params.source`` or, with ``"auto"``, the
first present in the dataset directory: a ``*.bag`` file, an RGBD folder (``rgbd/`` or
the directory itself with ``color/`` + ``depth/``), a stereo folder (``stereo/`` or the
directory itself with ``left/`` + ``right/``). ``dataset_dir`` may also be a ``.bag`` file.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from physanim.capture.bag_source import read_bag
from physanim.capture.folder_source import read_rgbd_folder, read_stereo_folder
from physanim.capture.frames import Capture, CaptureError
from physanim.capture.params import IngestParams

__all__ = ["Capture", "CaptureError", "find_source", "load_capture"]


def _find_bag(d: Path) -> Path | None:
    bags = sorted(d.glob("*.bag"))
    return bags[0] if bags else None


def _find_folder(d: Path, name: str, parts: tuple[str, str]) -> Path | None:
    for cand in (d / name, d):
        if all((cand / p).is_dir() for p in parts):
            return cand
    return None


def find_source(dataset_dir: Path, source: str = "auto") -> tuple[str, Path]:
    """(kind, path) of the recording to read in ``dataset_dir`` for ``source``."""
    d = Path(dataset_dir)
    if not d.exists():
        raise FileNotFoundError(f"{d}: dataset not found")
    if d.is_file():
        if d.suffix != ".bag" or source not in ("auto", "bag"):
            raise CaptureError(f"{d}: a file dataset must be a .bag (source={source!r})")
        return "bag", d
    finders = {
        "bag": lambda: _find_bag(d),
        "rgbd": lambda: _find_folder(d, "rgbd", ("color", "depth")),
        "stereo": lambda: _find_folder(d, "stereo", ("left", "right")),
    }
    kinds = list(finders) if source == "auto" else [source]
    for kind in kinds:
        path = finders[kind]()
        if path is not None:
            return kind, path
    want = {
        "bag": "a *.bag file",
        "rgbd": "rgbd/color + rgbd/depth",
        "stereo": "stereo/left + stereo/right",
    }
    raise CaptureError(f"{d}: no {' or '.join(want[k] for k in kinds)} found (source={source!r})")


def load_capture(
    dataset_dir: Path,
    params: IngestParams | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Capture:
    """Ingest the recording in ``dataset_dir``; see the module docstring and ``Capture``."""
    params = params or IngestParams()
    kind, path = find_source(Path(dataset_dir), params.source)
    reader = {"bag": read_bag, "rgbd": read_rgbd_folder, "stereo": read_stereo_folder}[kind]
    return reader(path, params, progress)

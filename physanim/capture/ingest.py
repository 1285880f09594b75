"""Capture ingest: read a RealSense bag, an Open3D RGBD folder or a stereo pair into a
``Capture`` (colour, metric depth, intrinsics, timestamps, validity statistics).

``load_capture`` picks the source named by ``params.source`` or, with ``"auto"``, the
first present in the dataset directory: a ``*.bag`` file, an RGBD folder (``rgbd/`` or
the directory itself with ``color/`` + ``depth/``), a stereo folder (``stereo/`` or the
directory itself with ``left/`` + ``right/``). ``dataset_dir`` may also be a ``.bag`` file.
The result is checked (``physanim.capture.validate``) before anything is computed from it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from physanim.capture.bag_source import read_bag
from physanim.capture.folder_source import IMAGE_SUFFIXES, read_rgbd_folder, read_stereo_folder
from physanim.capture.frames import Capture, CaptureError, CaptureWarning, Problem
from physanim.capture.params import IngestParams
from physanim.capture.validate import check_capture

__all__ = [
    "Capture", "CaptureError", "CaptureWarning", "find_source", "load_capture", "read_capture",
    "source_files",
]  # fmt: skip


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
        "bag": "a RealSense *.bag file",
        "rgbd": "an RGBD folder (rgbd/ or the dataset itself with color/, depth/, intrinsic.json)",
        "stereo": "a stereo folder (stereo/ or the dataset itself with left/, right/, "
        "calibration.yaml)",
    }
    raise CaptureError(
        f"{d}: no recording found; looked for {' or '.join(want[k] for k in kinds)} "
        f"(ingest.source={source}); see the README section 'Your own recording'"
    )


def has_recording(dataset_dir: Path) -> bool:
    """Whether ``dataset_dir`` holds a recording ``find_source`` finds (any kind)."""
    try:
        find_source(dataset_dir)
    except (FileNotFoundError, ValueError):
        return False
    return True


def source_files(kind: str, path: Path) -> list[Path]:
    """Exactly the files ingest reads for the source ``(kind, path)`` of ``find_source``:
    the bag; or the calibration file and the frame images (never anything else in the
    folder, such as the run directory of a dataset-root layout)."""
    if kind == "bag":
        return [path]
    calib, streams = {"rgbd": ("intrinsic.json", ("color", "depth")),
                      "stereo": ("calibration.yaml", ("left", "right"))}[kind]  # fmt: skip
    files = [path / calib] if (path / calib).is_file() else []
    for sub in streams:
        folder = path / sub
        if folder.is_dir():
            files += sorted(f for f in folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
    return files


def read_capture(
    dataset_dir: Path,
    params: IngestParams | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[Capture, list[Problem]]:
    """Read the recording in ``dataset_dir`` and check it (``physanim.capture.validate``);
    unreadable input raises ``CaptureError``, doubtful input is returned as problems."""
    params = params or IngestParams()
    kind, path = find_source(Path(dataset_dir), params.source)
    reader = {"bag": read_bag, "rgbd": read_rgbd_folder, "stereo": read_stereo_folder}[kind]
    capture = reader(path, params, progress)
    capture.kind, capture.origin = kind, str(path)
    problems, implausible = check_capture(capture, params)
    capture.implausible_depth = sorted(implausible)
    if implausible and params.implausible_depth == "drop":
        capture.depth[np.isin(capture.frame_index, list(implausible))] = np.nan
        capture.update_stats()
    problems = [Problem("warning", w) for w in capture.warnings] + problems
    return capture, problems


def load_capture(
    dataset_dir: Path,
    params: IngestParams | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Capture:
    """Ingest the recording in ``dataset_dir``; see the module docstring and ``Capture``.

    Errors found by the checks raise ``CaptureError`` (one line each); warnings are issued as
    ``CaptureWarning`` and kept in ``Capture.warnings``.
    """
    capture, problems = read_capture(dataset_dir, params, progress)
    errors = [p.message for p in problems if p.level == "error"]
    if errors:
        raise CaptureError("\n".join(errors))
    capture.warnings = [p.message for p in problems]
    for message in capture.warnings:
        warnings.warn(message, CaptureWarning, stacklevel=2)
    return capture

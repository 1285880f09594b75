"""Capture-input fuzzing: damaged copies of a small demo recording, ingested as a user's run
would (``load_capture``, which ``physanim run``'s ingest stage calls; ``physanim check``
calls its ``read_capture``), and judged against the undamaged recording's result.

Each damaged input must be either

- refused with a ``CaptureError`` (or ``FileNotFoundError``) whose message names the damaged
  file (``color/000001.png``, ``intrinsic.json``) and, for a damaged field, the field; or
- accepted, and then its result equals the undamaged one (colour, depth, intrinsics, frame
  numbers, timestamps, frame rate, depth scale). A bag has no checksums: damage smaller than
  what ingest's checks can see (``physanim.capture.validate.MIN_RUN`` pixels) may pass, so an
  accepted damaged bag may differ in at most 48 colour values and 16 depths, and have depth
  made invalid (zeroed), never more values than bytes were damaged.

Anything else (another exception: a traceback for the user; or a result that differs) is a
defect. ``damage(kind, rng)`` picks a mutation of that kind at random; ``judge`` runs one.
"""

from __future__ import annotations

import json
import random
import shutil
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from physanim.capture.frames import Capture, CaptureError
from physanim.capture.ingest import load_capture
from physanim.capture.params import IngestParams
from physanim.capture.validate import MIN_RUN

#: kinds of damaged input -> the recording (source) they belong to
KINDS = {
    "colour PNG": "rgbd",
    "depth PNG": "rgbd",
    "stereo PNG": "stereo",
    "intrinsics JSON": "rgbd",
    "calibration YAML": "stereo",
    "bag": "bag",
}


@dataclass
class Damage:
    """One damaged file: its kind, the mutation, the file, the damaged field (if any) and,
    for bags, how many bytes changed."""

    kind: str
    mutation: str
    file: Path
    field: str = ""
    changed_bytes: int = 0


@dataclass
class Outcome:
    """What ingest made of a damaged input: ``accepted`` (and equal to the undamaged
    result), ``refused`` (with a message naming the file and field), or a defect:
    ``traceback`` (another exception), ``unnamed`` (a refusal that does not name the file
    or field) or ``wrong`` (accepted but different)."""

    damage: Damage
    verdict: str
    message: str = ""

    @property
    def defect(self) -> bool:
        return self.verdict not in ("accepted", "refused")

    def line(self) -> str:
        d = self.damage
        what = f"{d.kind} {d.mutation}" + (f" {d.field}" if d.field else "")
        first = (self.message.splitlines() or [""])[0][:300]
        return f"{self.verdict}: {what} ({d.file.parent.name}/{d.file.name}): {first}"


@dataclass
class Pristine:
    """An undamaged demo recording (``root``: capture.bag, rgbd/, stereo/) and what ingest
    makes of each of its sources."""

    root: Path
    captures: dict[str, Capture] = field(default_factory=dict)

    @classmethod
    def make(cls, root: Path, n_frames: int = 3) -> Pristine:
        from physanim.capture.demo import generate_demo

        if not (root / "capture.bag").is_file():
            generate_demo(root, n_frames=n_frames, seed=0)
        out = cls(root)
        for source in ("bag", "rgbd", "stereo"):
            out.captures[source] = ingest(out.source_path(source), source)
        return out

    def source_path(self, source: str) -> Path:
        return self.root / ("capture.bag" if source == "bag" else source)

    def copy(self, source: str, work: Path) -> Path:
        """A fresh copy of ``source`` under ``work`` (emptied first); its path."""
        if work.exists():
            shutil.rmtree(work)
        work.mkdir(parents=True)
        src = self.source_path(source)
        if source == "bag":
            return Path(shutil.copy(src, work / src.name))
        return Path(shutil.copytree(src, work / source))


def ingest(path: Path, source: str) -> Capture:
    """``load_capture`` of ``path`` as ``source``, its warnings kept in the capture."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_capture(path, IngestParams(source=source))


# ---------------------------------------------------------------------------------------------
# byte-level damage (any file)


def _truncate(data: bytes, rng: random.Random) -> tuple[bytes, str, int]:
    n = rng.randrange(0, len(data))
    return data[:n], f"truncated to {n} of {len(data)} bytes", len(data) - n


def _offset(data: bytes, rng: random.Random, size: int = 1) -> int:
    """A random offset; a third each uniform, in the first and in the last 16 KiB (where
    headers and indices are)."""
    top = max(len(data) - size, 1)
    where = rng.randrange(3)
    if where == 1:
        return rng.randrange(min(16384, top))
    if where == 2:
        return rng.randrange(max(top - 16384, 0), top)
    return rng.randrange(top)


def _bitflip(data: bytes, rng: random.Random) -> tuple[bytes, str, int]:
    out = bytearray(data)
    n = rng.randint(1, 8)
    spots = {(_offset(data, rng), rng.randrange(8)) for _ in range(n)}
    for i, bit in spots:
        out[i] ^= 1 << bit
    return bytes(out), f"{len(spots)} bit(s) flipped", len({i for i, _ in spots})


def _block(data: bytes, rng: random.Random, zero: bool = False) -> tuple[bytes, str, int]:
    size = min(rng.choice((1, 16, 256, 4096)) * rng.randint(1, 4), len(data))
    at = _offset(data, rng, size)
    new = bytes(size) if zero else rng.randbytes(size)
    changed = sum(a != b for a, b in zip(data[at : at + size], new, strict=True))
    what = "zeroed" if zero else "random bytes over"
    return data[:at] + new + data[at + size :], f"{size} bytes at {at} {what}", changed


BYTE_MUTATIONS: dict[str, Callable[[bytes, random.Random], tuple[bytes, str, int]]] = {
    "truncate": _truncate,
    "bitflip": _bitflip,
    "random block": _block,
    "zero block": lambda d, r: _block(d, r, zero=True),
}

# ---------------------------------------------------------------------------------------------
# image-level damage (a frame re-encoded)


def _resized(img: np.ndarray, rng: random.Random) -> np.ndarray:
    h, w = img.shape[:2]
    while True:
        nh, nw = (
            (max(1, int(h * s)), max(1, int(w * s)))
            if rng.random() < 0.5 and (s := rng.choice((0.25, 0.5, 0.99, 1.01, 2.0)))
            else (h + rng.randint(-8, 8), w + rng.randint(-8, 8))
        )
        if (nh, nw) != (h, w):
            break
    if rng.random() < 0.5:  # cropped or padded
        out = np.zeros((nh, nw, *img.shape[2:]), img.dtype)
        ch, cw = min(h, nh), min(w, nw)
        out[:ch, :cw] = img[:ch, :cw]
        return out
    return cv2.resize(img, (nw, nh), interpolation=cv2.INTER_NEAREST)


def _recoded(path: Path, rng: random.Random, depth: bool) -> tuple[np.ndarray, str]:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    choices = (
        ["resize", "8-bit", "3 channels", "same pixels"]
        if depth
        else ["resize", "greyscale", "16-bit", "RGBA", "same pixels"]
    )
    what = rng.choice(choices)
    if what == "resize":
        return _resized(img, rng), what
    if what == "8-bit":
        return (img // 256).astype(np.uint8), what
    if what == "3 channels":
        return np.repeat(img[..., None], 3, axis=2), what
    if what == "greyscale":
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), what
    if what == "16-bit":
        return img.astype(np.uint16) * 257, what
    if what == "RGBA":
        return cv2.cvtColor(img, cv2.COLOR_BGR2BGRA), what
    return img, what


def damage_frame(root: Path, sub: tuple[str, ...], kind: str, rng: random.Random) -> Damage:
    """Damage one frame file of ``root/<one of sub>/``: bytes, or re-encoded."""
    folder = root / rng.choice(sub)
    target = rng.choice(sorted(folder.glob("*.png")))
    mutation = rng.choice([*BYTE_MUTATIONS, "re-encoded", "re-encoded", "empty", "appended"])
    data = target.read_bytes()
    if mutation in BYTE_MUTATIONS:
        new, what, n = BYTE_MUTATIONS[mutation](data, rng)
        target.write_bytes(new)
        return Damage(kind, f"{mutation} ({what})", target, changed_bytes=n)
    if mutation == "empty":
        target.write_bytes(b"")
        return Damage(kind, "empty file", target)
    if mutation == "appended":
        target.write_bytes(data + rng.randbytes(rng.randint(1, 512)))
        return Damage(kind, "bytes appended after the end", target)
    img, what = _recoded(target, rng, depth=folder.name == "depth")
    level = rng.randint(0, 9)
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, level])
    assert ok
    target.write_bytes(buf.tobytes())
    return Damage(kind, f"re-encoded: {what} {img.shape}", target)


# ---------------------------------------------------------------------------------------------
# field-level damage (calibration YAML, intrinsics JSON)


def _scaled(value: Any, factor: float) -> Any:
    if isinstance(value, dict) and "data" in value:
        return {**value, "data": [x * factor for x in value["data"]]}
    if isinstance(value, list):
        return [_scaled(v, factor) for v in value]
    return value * factor if isinstance(value, int | float) else value


def _matrix_rows(value: Any) -> list[list[float]] | None:
    """A matrix entry (OpenCV mapping, nested or flat list) as rows, if it is one."""
    if isinstance(value, dict) and "data" in value:
        return np.reshape(value["data"], (value["rows"], value["cols"])).tolist()
    if isinstance(value, list) and value and isinstance(value[0], list):
        return value
    return None


def _field_value(key: str, value: Any, rng: random.Random) -> tuple[Any, str]:
    """A damaged ``value`` of ``key`` (or ``...`` to delete it) and what was done."""
    ops = ["delete", "null", "string", "bool", "nan", "inf", "-inf", "negative", "zero",
           "x1000", "x0.001", "list", "mapping"]  # fmt: skip
    rows = _matrix_rows(value)
    if rows is not None:
        ops += ["transposed", "rows", "flat", "short", "long", "3x4", "strings", "rows/cols"]
    elif isinstance(value, list):  # Open3D's flat column-major matrix
        ops += ["transposed", "rows", "short", "long", "3x4", "strings"]
    op = rng.choice(ops)
    num = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}
    if op == "delete":
        return ..., op
    if op in num:
        return _fill(value, num[op], rng), f"a value set to {op}"
    simple = {"null": None, "string": "abc", "bool": True, "list": [1, 2], "mapping": {"a": 1}}
    if op in simple:
        return simple[op], f"set to {simple[op]!r}"
    if op == "negative":
        return _scaled(value, -1.0), op
    if op == "zero":
        return _scaled(value, 0.0), op
    if op.startswith("x"):
        return _scaled(value, float(op[1:])), f"scaled {op}"
    if isinstance(value, list) and rows is None:  # flat, column-major
        rows = np.reshape(value, (3, 3)).T.tolist() if len(value) == 9 else [value]
    arr = np.asarray(rows, dtype=float)
    if op == "transposed":
        return (arr.T.ravel().tolist() if isinstance(value, list) and _matrix_rows(value) is None
                else arr.T.tolist()), "transposed (wrong layout)"  # fmt: skip
    if op == "rows":
        return arr.tolist(), "as a list of rows (an accepted layout)"
    if op == "flat":
        return arr.ravel().tolist(), "flattened (row-major)"
    if op == "short":
        return arr.ravel().tolist()[:-1], "one number short"
    if op == "long":
        return [*arr.ravel().tolist(), 0.0], "one number too many"
    if op == "3x4":
        return np.hstack([arr, np.zeros((len(arr), 1))]).tolist(), "a column too many"
    if op == "strings":
        return [[str(x) for x in row] for row in arr.tolist()], "numbers as strings"
    # rows/cols of an OpenCV matrix that disagree with its data
    return {**value, "rows": value["cols"], "cols": value["rows"] + 1}, "rows/cols wrong"


def _fill(value: Any, x: float, rng: random.Random) -> Any:
    """``value`` with one number (at random) replaced by ``x``."""
    if isinstance(value, dict) and "data" in value:
        data = list(value["data"])
        data[rng.randrange(len(data))] = x
        return {**value, "data": data}
    if isinstance(value, list) and value:
        i = rng.randrange(len(value))
        return [*value[:i], _fill(value[i], x, rng), *value[i + 1 :]]
    return x


def damage_fields(path: Path, kind: str, rng: random.Random) -> Damage:
    """Damage ``path`` (JSON intrinsics or YAML calibration): a field, two fields swapped, or
    the file's bytes."""
    text = path.read_text()
    if rng.random() < 0.15:
        mutation = rng.choice(("truncate", "bitflip"))
        new, what, _ = BYTE_MUTATIONS[mutation](text.encode(), rng)
        path.write_bytes(new)
        return Damage(kind, f"{mutation} ({what})", path)
    if path.suffix == ".json":
        data = json.loads(text)
    else:
        from physanim.capture.stereo import _CalibrationLoader

        data = yaml.load(text.replace("%YAML 1.2", ""), Loader=_CalibrationLoader)  # noqa: S506
    keys = list(data)
    if rng.random() < 0.1:
        a, b = ("width", "height") if "width" in data else ("image_width", "image_height")
        if rng.random() < 0.5:
            a, b = rng.sample(keys, 2)
        data[a], data[b] = data[b], data[a]
        dmg = Damage(kind, f"{a} and {b} swapped", path, field=f"{a}|{b}")
    else:
        key = rng.choice(keys)
        value, what = _field_value(key, data[key], rng)
        if value is ...:
            del data[key]
        else:
            data[key] = value
        dmg = Damage(kind, what, path, field=key)
    if path.suffix == ".json":
        path.write_text(json.dumps(data, indent=1))
    else:
        path.write_text(yaml.safe_dump(data, sort_keys=False))
    return dmg


# ---------------------------------------------------------------------------------------------


def damage(kind: str, copy: Path, rng: random.Random) -> Damage:
    """Damage the copy ``copy`` of the source of ``kind`` (see ``KINDS``) at random."""
    if kind == "colour PNG":
        return damage_frame(copy, ("color",), kind, rng)
    if kind == "depth PNG":
        return damage_frame(copy, ("depth",), kind, rng)
    if kind == "stereo PNG":
        return damage_frame(copy, ("left", "right"), kind, rng)
    if kind == "intrinsics JSON":
        return damage_fields(copy / "intrinsic.json", kind, rng)
    if kind == "calibration YAML":
        return damage_fields(copy / "calibration.yaml", kind, rng)
    mutation = rng.choice(list(BYTE_MUTATIONS))
    new, what, n = BYTE_MUTATIONS[mutation](copy.read_bytes(), rng)
    copy.write_bytes(new)
    return Damage(kind, f"{mutation} ({what})", copy, changed_bytes=n)


def differences(cap: Capture, ref: Capture, bag: bool) -> tuple[list[str], int, int, int]:
    """(fields that differ, colour values that differ, depth values changed to another valid
    depth, depth values made invalid) of two captures."""
    out = []
    if cap.frame_index.tolist() != ref.frame_index.tolist():
        return [f"frames {cap.frame_index.tolist()} != {ref.frame_index.tolist()}"], 0, 0, 0
    if cap.color.shape != ref.color.shape or cap.depth.shape != ref.depth.shape:
        return [f"shape {cap.color.shape} != {ref.color.shape}"], 0, 0, 0
    if not np.allclose(cap.K, ref.K, rtol=1e-9, atol=0):
        out.append(f"K {cap.K.tolist()} != {ref.K.tolist()}")
    if cap.fps != ref.fps or cap.depth_scale != ref.depth_scale:
        out.append(f"fps/depth_scale {cap.fps}/{cap.depth_scale} != {ref.fps}/{ref.depth_scale}")
    if not np.allclose(cap.timestamps, ref.timestamps, rtol=0, atol=1e-3 if bag else 1e-12):
        out.append(f"timestamps {cap.timestamps.tolist()} != {ref.timestamps.tolist()}")
    n_color = int(np.count_nonzero(cap.color != ref.color))
    valid, was_valid = np.isfinite(cap.depth), np.isfinite(ref.depth)
    n_depth = int(np.count_nonzero(valid & (~was_valid | (cap.depth != ref.depth))))
    n_invalid = int(np.count_nonzero(~valid & was_valid))
    return out, n_color, n_depth, n_invalid


def named(message: str, dmg: Damage) -> bool:
    """Whether a refusal names the damaged file (its folder and name for frames) and field."""
    file = dmg.file.name if dmg.file.suffix != ".png" else f"{dmg.file.parent.name}/{dmg.file.name}"
    lines = [line for line in message.splitlines() if file in line]
    fields = dmg.field.split("|") if dmg.field else []
    return bool(lines) and (not fields or any(f in line for f in fields for line in lines))


def judge(pristine: Pristine, kind: str, rng: random.Random, work: Path) -> Outcome:
    """Damage a fresh copy of ``kind``'s source under ``work`` and ingest it."""
    source = KINDS[kind]
    copy = pristine.copy(source, work)
    dmg = damage(kind, copy, rng)
    try:
        cap = ingest(copy, source)
    except (CaptureError, FileNotFoundError) as exc:
        message = str(exc)
        return Outcome(dmg, "refused" if named(message, dmg) else "unnamed", message)
    except Exception:  # anything else reaches the user as a traceback
        return Outcome(dmg, "traceback", traceback.format_exc())
    ref = pristine.captures[source]
    diffs, n_color, n_depth, n_invalid = differences(cap, ref, source == "bag")
    if source == "bag":  # no checksums: damage below what the checks can see may pass
        small = n_color <= 3 * MIN_RUN and n_depth <= MIN_RUN
        within = n_color + n_depth + n_invalid <= dmg.changed_bytes
        if not (small and within):
            diffs.append(
                f"{n_color} colour values, {n_depth} depths and {n_invalid} valid depths differ "
                f"({dmg.changed_bytes} bytes changed; undetected damage may change at most "
                f"{3 * MIN_RUN} colour values and {MIN_RUN} depths, and make depth invalid)"
            )
    elif n_color or n_depth or n_invalid:
        diffs.append(f"{n_color} colour values, {n_depth + n_invalid} depths differ")
    if diffs:
        return Outcome(dmg, "wrong", "; ".join(diffs))
    return Outcome(dmg, "accepted", "; ".join(cap.warnings))

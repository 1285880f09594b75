"""The codec between dataclasses and Zarr groups: the arrays, attributes and subgroups inside
one stage output (``<stage>/<key>/...`` of the layout described in ``stage_store``)."""

from __future__ import annotations

import dataclasses
import functools
import typing
from typing import Any, TypeVar

import numpy as np
import zarr

T = TypeVar("T")

#: Target size of one chunk, bytes; arrays are chunked along their first (frame) axis only.
CHUNK_BYTES = 4 * 2**20


def frame_chunks(shape: tuple[int, ...], itemsize: int) -> tuple[int, ...]:
    """Chunk shape that splits only the first axis, about CHUNK_BYTES per chunk, >= 1 frame."""
    if not shape:
        return ()
    per_frame = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    n = max(1, min(shape[0], CHUNK_BYTES // max(per_frame, 1)))
    return (n, *shape[1:])


def write_array(group: zarr.Group, name: str, data: np.ndarray) -> zarr.Array:
    """Write ``data`` as array ``name`` of ``group``, chunked by frames (first axis)."""
    data = np.asarray(data)
    chunks = frame_chunks(data.shape, data.dtype.itemsize) if data.ndim else ()
    arr = group.create_array(name, shape=data.shape, dtype=data.dtype, chunks=chunks or "auto")
    arr[...] = data
    return arr


def stored_name(f: dataclasses.Field[Any]) -> str:
    """The name a dataclass field is stored under: ``metadata={"stored": ...}`` or its own."""
    return str(f.metadata.get("stored", f.name))


def _fields(record: object) -> tuple[dataclasses.Field[Any], ...]:
    """The fields of a dataclass or dataclass instance; TypeError naming any other type."""
    if not dataclasses.is_dataclass(record):
        name = record.__name__ if isinstance(record, type) else type(record).__name__
        raise TypeError(f"cannot store or read {name}: not a dataclass")
    return dataclasses.fields(record)


def write_dataclass(group: zarr.Group, record: object, prefix: str = "") -> None:
    """Write each numpy-array field of dataclass ``record`` as ``<prefix>/<field>``.

    Scalar fields (numbers, strings, bools, lists of them) go to the group's attributes;
    a nested dataclass goes to the subgroup ``<prefix>/<field>``, a non-empty dict of
    dataclasses to one subgroup per key.  A field's ``metadata={"stored": name}`` stores it
    under another name (``""``: a dict of dataclasses directly in ``<prefix>``).
    """
    target = group.require_group(prefix) if prefix else group
    for f in _fields(record):
        value, name = getattr(record, f.name), stored_name(f)
        if isinstance(value, np.ndarray):
            write_array(target, name, value)
        elif _is_record(value):
            write_dataclass(target, value, name)
        elif isinstance(value, dict) and value and all(map(_is_record, value.values())):
            for k, v in value.items():
                write_dataclass(target, v, f"{name}/{k}" if name else k)
        elif isinstance(value, str | int | float | bool | list | tuple | dict) or value is None:
            target.attrs[name] = value
        else:
            raise TypeError(f"cannot store field {f.name!r} of type {type(value).__name__}")


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints`` of a dataclass, once per class."""
    return typing.get_type_hints(cls)


def _is_record(value: object) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _dataclass_of(cls: type, name: str) -> type:
    """The dataclass type of field ``name`` of ``cls`` (``X`` or ``X | None``)."""
    hint = _hints(cls)[name]
    for t in (hint, *typing.get_args(hint)):
        if isinstance(t, type) and dataclasses.is_dataclass(t):
            return t
    raise TypeError(f"{cls.__name__}.{name}: stored as a group, but {hint} is not a dataclass")


def read_dataclass(cls: type[T], group: zarr.Group) -> T:
    """Rebuild a dataclass written by ``write_dataclass`` from its group.

    Nested dataclass fields are read from their subgroups; a field with
    ``metadata={"lazy": True}`` is returned as the read-only Zarr array (sliced by the
    reader: large per-frame arrays), the others as numpy arrays or attribute values.  A field
    absent from the group takes its default; without one, KeyError names the field and group.
    """
    kwargs: dict[str, Any] = {}
    for f in _fields(cls):
        if not f.init:
            continue
        name = stored_name(f)
        hint = _hints(cls)[f.name] if name == "" or name in group else None
        if typing.get_origin(hint) is dict:  # a dict of dataclasses, one subgroup per key
            record = typing.get_args(hint)[1]
            where = group[name] if name else group
            kwargs[f.name] = {k: read_dataclass(record, g) for k, g in sorted(where.groups())}
        elif name in group:
            node = group[name]
            if isinstance(node, zarr.Group):  # a nested dataclass
                kwargs[f.name] = read_dataclass(_dataclass_of(cls, f.name), node)
            else:
                kwargs[f.name] = node if f.metadata.get("lazy") else node[...]
        elif name in group.attrs:
            kwargs[f.name] = group.attrs[name]
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise KeyError(f"{group.store}/{group.path}: no '{name}' ({cls.__name__}.{f.name})")
    return cls(**kwargs)

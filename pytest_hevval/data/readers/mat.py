"""MATLAB MAT files: v5 through scipy.io (after a byte-level check), v7.3 as HDF5."""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from types import ModuleType
from typing import Any

import numpy as np

from ...errors import DataError, did_you_mean
from ..record import Record, SourceOptions
from ._common import (
    _as_list,
    _as_values,
    _corrupt,
    _import,
    _is_numeric_dtype,
    _kind_name,
    _no_rows,
    _table_record,
    _time_base,
    _vector_plan,
)
from .guards.mat5 import _mat5_problem
from .hdf5 import _is_hdf5, _open_hdf5, _read_hdf5_group, _vector_length

_MAT_NUMERIC = {
    "double",
    "single",
    "logical",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
}


def _read_mat(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    if _is_hdf5(path):
        with _open_hdf5(path, "MAT") as handle:
            record = _read_hdf5_group(
                path, handle, options.group, _as_list(columns), options, matlab=True
            )
        record.meta["mat_version"] = "7.3"
        return record
    return _read_mat5(path, _as_list(columns), options)


def _read_mat5(path: str, columns: list[str] | None, options: SourceOptions) -> Record:
    sio = _import("scipy.io", "reading MAT files", "mat")
    problem = _mat5_problem(path)
    if problem is not None:
        raise _corrupt(path, "MAT", ValueError(problem))
    try:
        with _mat_warnings_as_errors():
            variables = sio.whosmat(path)
    except Exception as exc:
        # scipy raises a mix of ValueError, TypeError, OSError and its own MatReadError for
        # damaged files; all mean the same to the user.
        raise _corrupt(path, "MAT", exc) from None
    group = options.group
    if group:
        top = group.split(".")[0]
        structs = [name for name, _, cls in variables if cls == "struct"]
        if top not in {name for name, _, _ in variables}:
            suggestion = did_you_mean(top, structs)
            listing = ", ".join(repr(s) for s in structs[:12]) or "none"
            raise DataError(
                f"no struct {group!r} in this file",
                file=path,
                key="group",
                hint=suggestion or f"set `group:` to one of the structs: {listing}",
            )
        loaded = _loadmat(sio, path, [top])
        node: Any = loaded[top]
        for part in group.split(".")[1:]:
            if not isinstance(node, dict) or part not in node:
                raise DataError(
                    f"no struct {group!r} in this file",
                    file=path,
                    key="group",
                    hint=did_you_mean(part, node if isinstance(node, dict) else [])
                    or "check the struct path (fields are separated by '.')",
                )
            node = node[part]
        if not isinstance(node, dict):
            raise DataError(
                f"{group!r} is not a struct",
                file=path,
                key="group",
                hint="set `group:` to a struct whose fields are the channels",
            )
        arrays = {
            str(k): np.atleast_1d(np.asarray(v))
            for k, v in node.items()
            if isinstance(v, np.ndarray | float | int)
        }
        lengths = {n: a.shape[0] for n, a in arrays.items() if a.ndim == 1}
        numeric = [n for n in lengths if _is_numeric_dtype(arrays[n].dtype)]
        names = list(lengths)
        time_name, wanted, numeric = _vector_plan(path, lengths, numeric, columns, options)
        data = {n: arrays[n] for n in [time_name, *wanted]}
    else:
        vectors: dict[str, str] = {}
        lengths = {}
        for name, shape, cls in variables:
            length = _vector_length(tuple(shape))
            if length is not None:
                vectors[name] = cls
                lengths[name] = length
        names = list(vectors)
        numeric = [n for n, cls in vectors.items() if cls in _MAT_NUMERIC]
        if not any(lengths[n] >= 2 for n in numeric):
            structs = [name for name, _, cls in variables if cls == "struct"]
            hint = (
                f"set `group:` to the struct that holds the channels: "
                f"{', '.join(repr(s) for s in structs[:12])}"
                if structs
                else "save one vector per channel plus a time vector"
            )
            raise DataError("no numeric vectors in this file", file=path, key="group", hint=hint)
        time_name, wanted, numeric = _vector_plan(path, lengths, numeric, columns, options)
        for name in [time_name, *wanted]:
            if vectors[name] not in _MAT_NUMERIC:
                raise DataError(
                    f"holds a MATLAB {vectors[name]}, not numbers",
                    file=path,
                    column=name,
                    hint="choose a numeric variable",
                )
        loaded = _loadmat(sio, path, list(dict.fromkeys([time_name, *wanted])))
        data = {n: np.atleast_1d(np.asarray(loaded[n])).reshape(-1) for n in [time_name, *wanted]}

    time_raw = data[time_name]
    if not _is_numeric_dtype(time_raw.dtype):
        raise DataError(
            f"the time column holds {_kind_name(time_raw.dtype)}, not numbers",
            file=path,
            column=time_name,
            hint="set `time:` to the numeric time variable",
        )
    if time_raw.size == 0:
        raise _no_rows(path)
    time, start_meta = _time_base(path, time_name, time_raw, options)
    values = {n: _as_values(path, n, data[n]) for n in wanted}
    meta: dict[str, Any] = {"mat_version": "5", **start_meta}
    if group:
        meta["group"] = group
    return _table_record(path, time_name, time, values, available=names, numeric=numeric, meta=meta)


@contextmanager
def _mat_warnings_as_errors() -> Iterator[None]:
    """Raise scipy's warnings while reading a MAT file instead of letting them through.

    They all describe a damaged file ("We do not support byte ordering 'VAX D-float';
    returned data may be corrupt", duplicate or unreadable variables), so the data must not be
    used; and under ``-W error`` a warning would escape as an exception of its own.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def _loadmat(sio: ModuleType, path: str, names: list[str]) -> dict[str, Any]:
    try:
        with _mat_warnings_as_errors():
            loaded: dict[str, Any] = sio.loadmat(path, variable_names=names, simplify_cells=True)
    except Exception as exc:
        # See _read_mat5: scipy's errors for damaged files have no common base class.
        raise _corrupt(path, "MAT", exc) from None
    return loaded

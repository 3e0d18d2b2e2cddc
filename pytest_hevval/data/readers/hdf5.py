"""HDF5 (and MATLAB v7.3, which is HDF5) through h5py."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ...errors import DataError, did_you_mean
from ..record import Record, SourceOptions
from ._common import (
    ValueArray,
    _as_list,
    _as_values,
    _corrupt,
    _import,
    _is_numeric_dtype,
    _kind_name,
    _no_rows,
    _not_numbers,
    _table_record,
    _time_base,
    _vector_plan,
)
from .guards.hdf5 import (
    _HDF5_SIGNATURE,
    _hdf5_get_checked,
    _hdf5_groups,
    _hdf5_name,
    hdf5_external_links,
)

# A MATLAB v7.3 file is HDF5 with a 512-byte (or larger power-of-two) user block in front.


_HDF5_SIGNATURE_OFFSETS = (0, 512, 1024, 2048)


@contextmanager
def _open_hdf5(path: str, kind: str) -> Iterator[Any]:
    h5py = _import("h5py", f"reading {kind} files", "hdf5" if kind == "HDF5" else "mat")
    try:
        handle = h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise _corrupt(path, kind, exc) from None
    with handle:
        try:
            yield handle
        except DataError:
            raise
        except (RuntimeError, OSError, KeyError, ValueError) as exc:
            # A damaged object header or heap surfaces only when the group is walked, as
            # RuntimeError ("Object visitation failed") or OSError from the HDF5 library.
            raise _corrupt(path, kind, exc) from None


def _read_hdf5(path: str, columns: Iterable[str] | None, options: SourceOptions) -> Record:
    with _open_hdf5(path, "HDF5") as handle:
        return _read_hdf5_group(
            path, handle, options.group, _as_list(columns), options, matlab=False
        )


def _read_hdf5_group(
    path: str,
    handle: Any,
    group: str | None,
    columns: list[str] | None,
    options: SourceOptions,
    *,
    matlab: bool,
) -> Record:
    import h5py

    key = "/" if not group else "/" + group.replace(".", "/").strip("/")
    node = _hdf5_get_checked(path, handle, key)
    if node is None or not isinstance(node, h5py.Group):
        groups = _hdf5_groups(path, handle)
        what = "struct" if matlab else "group"
        problem = (
            f"no {what} {group!r} in this file"
            if node is None
            else f"{group!r} is a dataset, not a {what}"
        )
        suggestion = did_you_mean(str(group), groups)
        listing = ", ".join(repr(g) for g in groups[:12]) if groups else "none"
        raise DataError(
            problem,
            file=path,
            key="group",
            hint=suggestion or f"set `group:` to one of: {listing}",
        )
    datasets: dict[str, Any] = {}
    # Links into other files are refused before any object is looked up: a look-up follows.
    for raw_name, (file_name, target) in hdf5_external_links(node).items():
        _refuse_other_files(path, _hdf5_name(raw_name), h5py.ExternalLink(file_name, target))
    for raw_name, obj in node.items():
        name = _hdf5_name(raw_name)
        if name.startswith("#") or not isinstance(obj, h5py.Dataset):
            continue
        _refuse_other_files(path, name, obj)
        if _vector_length(obj.shape) is not None:
            datasets[name] = obj
        elif columns is not None and name in columns:
            raise DataError(
                f"is a dataset of shape {tuple(obj.shape)}, not one channel",
                file=path,
                column=name,
                hint="store each channel as a 1-D dataset (one value per time step)",
            )
    names = list(datasets)
    if not names:
        where = "the file root" if key == "/" else f"group {key!r}"
        subgroups = [g for g in _hdf5_groups(path, handle) if g]
        hint = (
            "store one 1-D dataset per channel plus a time dataset"
            + (
                f", or set `group:` to one of: {', '.join(repr(g) for g in subgroups[:12])}"
                if subgroups
                else ""
            )
            + "; pandas HDFStore files are not supported: write Parquet instead"
        )
        raise DataError(f"no 1-D datasets in {where}", file=path, key="group", hint=hint)

    def is_numeric(name: str) -> bool:
        dataset = datasets[name]
        matlab_class = _attr_text(dataset.attrs.get("MATLAB_class"))
        return _is_numeric_dtype(dataset.dtype) and matlab_class != "char"

    numeric = [n for n in names if is_numeric(n)]
    lengths = {n: _vector_length(datasets[n].shape) or 0 for n in names}
    time_name, wanted, numeric = _vector_plan(path, lengths, numeric, columns, options)
    if not is_numeric(time_name):
        raise DataError(
            f"the time column holds {_kind_name(datasets[time_name].dtype)}, not numbers",
            file=path,
            column=time_name,
            hint="set `time:` to the numeric time dataset",
        )
    try:
        time_raw = np.asarray(datasets[time_name][()]).reshape(-1)
        raw = {n: np.asarray(datasets[n][()]).reshape(-1) for n in wanted}
    except (OSError, ValueError, KeyError) as exc:
        raise _corrupt(path, "MAT" if matlab else "HDF5", exc) from None
    if time_raw.size == 0:
        raise _no_rows(path)
    time, start_meta = _time_base(path, time_name, time_raw, options)
    values: dict[str, ValueArray] = {}
    for name in wanted:
        if not is_numeric(name):
            kind = (
                "text" if _is_numeric_dtype(datasets[name].dtype) else _kind_name(raw[name].dtype)
            )
            raise _not_numbers(path, name, str(kind))
        values[name] = _as_values(path, name, raw[name])
    units = {
        n: _attr_text(datasets[n].attrs.get("unit", datasets[n].attrs.get("units")))
        for n in [time_name, *wanted]
    }
    meta: dict[str, Any] = {"group": key, **start_meta}
    return _table_record(
        path, time_name, time, values, available=names, numeric=numeric, units=units, meta=meta
    )


def _refuse_other_files(path: str, name: str, item: Any) -> None:
    """A link or a dataset whose data lie in another file is refused: a spec and its data come
    from the change a CI gate judges, and must not make hevval read (and publish) a file the
    spec does not name, such as ``../outside/secret.txt`` or ``/etc/passwd``."""
    import h5py

    if isinstance(item, h5py.ExternalLink):
        elsewhere = f"a link to {item.path!r} in the file {item.filename!r}"
    elif isinstance(item, h5py.Dataset) and item.external:
        files = sorted({str(entry[0]) for entry in item.external})
        elsewhere = "stored outside the file, in " + ", ".join(repr(f) for f in files)
    elif isinstance(item, h5py.Dataset) and item.is_virtual:
        files = sorted({str(source.file_name) for source in item.virtual_sources()})
        elsewhere = "a virtual dataset of " + ", ".join(repr(f) for f in files)
    else:
        return
    raise DataError(
        f"{elsewhere}: hevval reads only the data file the spec names",
        file=path,
        column=name,
        hint="copy the data into this file (for example with `h5repack`), or name the file "
        "that holds them in the spec",
    )


def _vector_length(shape: tuple[int, ...]) -> int | None:
    """Length of a 1-D array, also written as a row or column matrix (MATLAB's habit)."""
    if len(shape) == 1:
        return shape[0]
    if len(shape) == 2 and 1 in shape:
        return max(shape)
    return None


def _attr_text(value: Any) -> str | None:
    if value is None:
        return None
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.size == 1:
        return _attr_text(value.reshape(-1)[0])
    if isinstance(value, np.bytes_):
        return bytes(value).decode("utf-8", errors="replace")
    return str(value)


def _is_hdf5(path: str) -> bool:
    with open(path, "rb") as stream:
        head = stream.read(max(_HDF5_SIGNATURE_OFFSETS) + len(_HDF5_SIGNATURE))
    return any(
        head[o : o + len(_HDF5_SIGNATURE)] == _HDF5_SIGNATURE for o in _HDF5_SIGNATURE_OFFSETS
    )

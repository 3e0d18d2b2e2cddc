"""Models that run themselves: a Python callable given the measured inputs.

A spec is trusted code, like a ``conftest.py``: naming ``callable: "pkg.mod:function"`` imports
and runs that function. Nothing runs unless a spec names it.
"""

from __future__ import annotations

import hashlib
import importlib
import sys
import traceback
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DataError, HevvalError
from .record import Channel, Record, SourceOptions
from .runtime import measure_call

__all__ = [
    "callable_identity",
    "import_callable",
    "record_from_frame",
    "reference_frame",
    "run_callable",
]


@contextmanager
def _search_path(folders: Iterable[Path]) -> Iterator[None]:
    added = [str(f) for f in folders if str(f) not in sys.path]
    sys.path[:0] = added
    try:
        yield
    finally:
        for folder in added:
            if folder in sys.path:
                sys.path.remove(folder)


def import_callable(reference: str, folders: Iterable[Path], *, source: str) -> Callable[..., Any]:
    """Import ``module:function`` with ``folders`` (the spec's folder, the rootdir) importable."""
    module_name, _, attribute = reference.partition(":")
    with _search_path(folders):
        try:
            module = importlib.import_module(module_name)
        except (Exception, SystemExit) as exc:
            raise DataError(
                f"cannot import the model module {module_name!r}: {type(exc).__name__}: {exc}",
                file=source,
                key="model.callable",
                hint="the module path is resolved from the spec's folder and the rootdir",
            ) from None
    target: Any = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise DataError(
                f"module {module_name!r} has no attribute {attribute!r}",
                file=source,
                key="model.callable",
            )
        target = getattr(target, part)
    if not callable(target):
        raise DataError(f"{reference!r} is not callable", file=source, key="model.callable")
    return target  # type: ignore[no-any-return]


def callable_identity(reference: str) -> dict[str, str]:
    """The file of an imported model callable's module and its SHA-256 (empty when the module
    has no file): what names the model's code in an evidence record. Only that file: modules
    it imports and data files it reads are not covered."""
    module = sys.modules.get(reference.partition(":")[0])
    file = getattr(module, "__file__", None)
    if not file:
        return {}
    try:
        digest = hashlib.sha256(Path(file).read_bytes()).hexdigest()
    except OSError:
        return {"module_file": str(file)}
    return {"module_file": str(file), "module_sha256": digest}


def reference_frame(reference: Record, inputs: Iterable[str], time_name: str) -> Any:
    """The measured inputs as a pandas DataFrame on the reference's own time base."""
    import pandas as pd

    names = list(dict.fromkeys(inputs))
    channels = [reference.channel(n) for n in names]
    base = _finest(channels) if channels else _finest(list(reference.channels.values()))
    data: dict[str, Any] = {time_name: base}
    for name, channel in zip(names, channels, strict=True):
        if channel.time is base or np.array_equal(channel.time, base):
            data[name] = np.asarray(channel.values)
        else:
            data[name] = np.interp(base, channel.time, np.asarray(channel.values, dtype=float))
    return pd.DataFrame(data)


def _finest(channels: list[Channel]) -> np.ndarray:
    if not channels:
        raise DataError("the reference has no channels to hand to the model")
    return max(channels, key=lambda c: c.time.shape[0]).time


def record_from_frame(
    frame: Any, time_name: str, source: str, options: SourceOptions | None = None
) -> Record:
    """Convert a model's returned DataFrame into a :class:`Record`, checking its shape.

    Its time column is read by the rule every data file's is (``options``: the spec's
    ``model:`` keys, ``time_scale`` among them): seconds, another unit, datetimes, ISO-8601
    text or epoch numbers. A column of text is kept as a name only, so asking for it says it
    holds no numbers."""
    import pandas as pd

    from .readers._common import _kind_name, _time_base

    if not isinstance(frame, pd.DataFrame):
        raise DataError(
            f"the model returned {type(frame).__name__}, not a pandas DataFrame",
            file=source,
            hint="return a DataFrame with a time column and one column per signal",
        )
    if time_name not in frame.columns:
        from .record import missing_column

        error = missing_column(
            source, time_name, [str(c) for c in frame.columns], where="in the model's output"
        )
        raise DataError(
            "the model output has no time column " + repr(time_name),
            file=source,
            column=time_name,
            hint=(error.hint or "") + "; set model.time to its name",
        )
    if len(frame) < 2:
        raise DataError(
            f"the model output holds {len(frame)} rows; a time series needs at least 2",
            file=source,
            column=time_name,
        )
    time, start = _time_base(
        source, time_name, frame[time_name].to_numpy(), options or SourceOptions()
    )
    channels: dict[str, Channel] = {}
    numeric: list[str] = []
    not_numeric: dict[str, str] = {}
    for column in frame.columns:
        name = str(column)
        if name == time_name:
            continue
        series = frame[column]
        if not (pd.api.types.is_numeric_dtype(series) or pd.api.types.is_bool_dtype(series)):
            not_numeric[name] = _kind_name(np.asarray(series).dtype)
            continue
        values = np.asarray(series, dtype=np.float64)
        channels[name] = Channel(time=time, values=values)
        numeric.append(name)
    return Record(
        source=source,
        channels=channels,
        available=tuple(str(c) for c in frame.columns),
        numeric=tuple(numeric),
        meta={"model_output": True, "not_numeric": not_numeric, **start},
    )


def run_callable(
    reference_to: str,
    reference: Record,
    *,
    inputs: Iterable[str],
    params: dict[str, Any],
    reference_time: str,
    model_time: str,
    folders: Iterable[Path],
    spec_file: str,
    options: SourceOptions | None = None,
    scored: Iterable[str] = (),
) -> Record:
    """Run ``module:function(reference_frame, **params)`` and return its output as a Record
    (``options``: how to read its time column, from the spec's ``model:``; ``scored``: the
    measured channels the spec scores, which it gets only when they are asked for)."""
    function = import_callable(reference_to, folders, source=spec_file)
    frame = reference_frame(reference, inputs, reference_time)
    label = f"model {reference_to}"
    try:
        with _search_path(folders):
            output, cost = measure_call(lambda: function(frame, **params))
    except HevvalError:
        raise
    except SystemExit as exc:
        # sys.exit in a model would end the run with its code and no result: a gate that
        # passes without scoring anything.
        raise DataError(
            f"the model called sys.exit({exc.code!r}) instead of returning its output",
            file=spec_file,
            key="model.callable",
            hint=f"make {reference_to} return a DataFrame (with the time column) instead",
        ) from None
    except Exception as exc:
        where = _model_line(exc, folders)
        given = [str(c) for c in frame.columns]
        missing = exc.args[0] if isinstance(exc, KeyError) and exc.args else None
        if isinstance(missing, str) and missing not in given:
            in_file = missing in reference.available
            if missing in set(scored):
                raise DataError(
                    f"the model asked for the column {missing!r}{where}, a measured signal "
                    "the spec scores: a model handed it can pass by copying it",
                    file=spec_file,
                    key="model.inputs",
                    hint=f"if the model is meant to be driven by it, list {missing!r} under "
                    "`driven_by:` under `model:` in the spec; else the model must compute it",
                ) from None
            raise DataError(
                f"the model asked for the column {missing!r}{where}, which it was not given: "
                "it receives only the columns the spec names"
                + (" (the data file has this one)" if in_file else "")
                + f"; it got {_listing(given)}",
                file=spec_file,
                key="model.inputs",
                hint=f"add {missing!r} to `inputs:` under `model:` in the spec"
                if in_file
                else "add the column to `inputs:` under `model:` in the spec, with the name the "
                "data file gives it",
            ) from None
        raise DataError(
            f"the model raised {type(exc).__name__}: {exc}{where}",
            file=spec_file,
            key="model.callable",
            hint=f"run {reference_to} on the columns it was given ({_listing(given)}; "
            "`inputs:` under `model:` chooses them) to debug it",
        ) from None
    record = record_from_frame(output, model_time, label, options)
    record.meta["cost"] = cost
    return record


def _model_line(exc: BaseException, folders: Iterable[Path]) -> str:
    """`` at models/ev.py:212``: the deepest line of the model's own code in the traceback
    (a line inside pandas or numpy says nothing about the model), else the deepest line."""
    frames = traceback.extract_tb(exc.__traceback__)[1:]
    if not frames:
        return ""
    roots = [Path(folder).resolve() for folder in folders]

    def own(filename: str) -> Path | None:
        path = Path(filename).resolve()
        for root in roots:
            if path.is_relative_to(root) and "site-packages" not in path.parts:
                return path.relative_to(root)
        return None

    for frame in reversed(frames):
        relative = own(frame.filename)
        if relative is not None:
            return f" at {relative.as_posix()}:{frame.lineno}"
    return f" at {Path(frames[-1].filename).name}:{frames[-1].lineno}"


def _listing(names: list[str], shown: int = 12) -> str:
    """Names for a message: all of a few, the first ``shown`` of many."""
    quoted = ", ".join(repr(n) for n in names[:shown])
    return f"[{quoted}]" if len(names) <= shown else f"[{quoted}, … {len(names) - shown} more]"

"""Run an FMU (FMI 1/2/3, co-simulation or model exchange) on measured inputs, with fmpy.

The model is driven by channels of the reference record, so a validation compares the model
with the measurement it was fed. Every failure, from a damaged FMU file to an error inside the
model, becomes a :class:`~pytest_hevval.errors.DataError` naming the FMU file and what failed.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import DataError, MissingExtraError, did_you_mean
from ..files import check_input
from .record import Channel, Record
from .runtime import measure_call

__all__ = ["run_fmu"]

FloatArray = npt.NDArray[np.float64]

# fmpy log status codes from "warning" upwards; the model's own words for what went wrong.
_LOG_WARNING = 1
_LOG_KEEP = 5
_STATUS_FATAL = 4


def run_fmu(
    fmu_path: str,
    reference: Record,
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    *,
    start_time: float,
    stop_time: float,
    step_size: float | None = None,
    parameters: Mapping[str, float] | None = None,
) -> Record:
    """Simulate ``fmu_path`` fed by ``reference`` channels; return the outputs as a record.

    Parameters
    ----------
    fmu_path
        The ``.fmu`` file (or a folder holding an extracted FMU).
    reference
        The measured record whose channels drive the FMU inputs.
    inputs
        FMU input variable → reference channel name. The inputs are given on the union of
        the channels' time stamps and interpolated linearly by fmpy in between.
    outputs
        Signal name to produce → FMU variable to record.
    start_time, stop_time
        Simulation window in seconds; every input channel must cover it.
    step_size
        Communication step (co-simulation) and output interval. None lets fmpy choose from
        the FMU's default experiment.
    parameters
        Start values for FMU variables (parameters or initial states).

    Returns
    -------
    Record
        One channel per ``outputs`` key, all sharing the simulation's time stamps.
    """
    fmpy = _import_fmpy()
    fmu_path = os.fspath(fmu_path)
    parameters = dict(parameters or {})
    _check_window(fmu_path, start_time, stop_time, step_size)
    if not os.path.exists(fmu_path):
        raise DataError("FMU file not found", file=fmu_path, hint="check the path")
    try:
        check_input(fmu_path)
    except OSError as exc:
        raise DataError(
            f"cannot read the FMU: {exc.strerror or exc}", file=fmu_path, hint="name the .fmu file"
        ) from None

    try:
        description = fmpy.read_model_description(fmu_path, validate=False)
    except Exception as exc:
        # fmpy raises zipfile, XML and plain exceptions alike for a file that is no FMU.
        raise DataError(
            f"cannot read the FMU's model description ({_first_line(exc)})",
            file=fmu_path,
            hint="check that this is an FMU (a zip with modelDescription.xml) and not damaged",
        ) from None

    variables = {v.name: v for v in description.modelVariables}
    _check_variables(fmu_path, variables, inputs, outputs, parameters)
    signals = _input_signals(fmu_path, reference, inputs, variables, start_time, stop_time)
    fmi_type = "CoSimulation" if description.coSimulation is not None else "ModelExchange"

    messages: list[str] = []

    def logger(*args: Any) -> None:
        # fmpy passes (component, instance, status, category, message) as bytes/ints.
        status, message = args[2], args[-1]
        if isinstance(status, int) and status >= _LOG_WARNING:
            text = message.decode("utf-8", "replace") if isinstance(message, bytes) else message
            messages.append(str(text).strip())
            del messages[:-_LOG_KEEP]

    with tempfile.TemporaryDirectory(prefix="hevval-fmu-", ignore_cleanup_errors=True) as unzipdir:
        # Extracting here (not inside fmpy) guarantees clean-up when the model fails.
        try:
            if os.path.isdir(fmu_path):
                unzipdir = fmu_path
            else:
                fmpy.extract(fmu_path, unzipdir=unzipdir)
            instance = fmpy.instantiate_fmu(unzipdir, description, fmi_type=fmi_type, logger=logger)
        except Exception as exc:
            raise _failure(fmu_path, "cannot load the FMU's binary", exc, messages) from None
        fatal = False
        steps = 0

        def count_step(*_: Any) -> bool:
            nonlocal steps
            steps += 1
            return True

        try:
            result, cost = measure_call(
                lambda: fmpy.simulate_fmu(
                    unzipdir,
                    validate=False,
                    start_time=start_time,
                    stop_time=stop_time,
                    step_size=step_size,
                    output_interval=step_size,
                    fmi_type=fmi_type,
                    start_values=parameters,
                    input=signals,
                    output=list(dict.fromkeys(outputs.values())),
                    model_description=description,
                    fmu_instance=instance,
                    step_finished=count_step,
                )
            )
        except Exception as exc:
            fatal = getattr(exc, "status", None) == _STATUS_FATAL
            raise _failure(
                fmu_path, "the model failed during the simulation", exc, messages
            ) from None
        finally:
            # After a fatal status FMI allows no further call, not even freeing; freeing
            # anyway unloads the model's library under objects that still use it.
            if not fatal:
                _free(instance)

    record = _result_record(fmu_path, result, outputs, variables, description, fmi_type)
    record.meta["cost"] = cost
    record.meta["steps"] = steps
    return record


def _import_fmpy() -> Any:
    try:
        import fmpy
    except ImportError:
        raise MissingExtraError.for_extra("running FMUs", "fmu", "fmpy") from None
    return fmpy


def _first_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return lines[0].rstrip(".") if lines else type(exc).__name__


def _failure(path: str, what: str, exc: BaseException, messages: list[str]) -> DataError:
    said = f"; the model logged: {messages[-1]}" if messages else ""
    return DataError(
        f"{what} ({_first_line(exc)}){said}",
        file=path,
        hint="check the inputs, parameters and window; fmpy.simulate_fmu with "
        "debug_logging=True shows the model's full log",
    )


def _free(instance: Any) -> None:
    # Freeing after a failed run can fail again; the first failure is the one reported.
    with contextlib.suppress(Exception):
        instance.freeInstance()


def _check_window(path: str, start: float, stop: float, step: float | None) -> None:
    if not (np.isfinite(start) and np.isfinite(stop)) or stop <= start:
        raise DataError(
            f"the simulation window is empty or not finite (start_time={start}, stop_time={stop})",
            file=path,
            hint="set stop_time after start_time",
        )
    if step is not None and (not np.isfinite(step) or step <= 0 or step > stop - start):
        raise DataError(
            f"step_size={step} does not fit the window {start}..{stop} s",
            file=path,
            key="step_size",
            hint="use a positive step smaller than the window",
        )


def _check_variables(
    path: str,
    variables: Mapping[str, Any],
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    parameters: Mapping[str, float],
) -> None:
    model_inputs = [n for n, v in variables.items() if v.causality == "input"]
    for name in inputs:
        if name not in variables:
            raise _no_variable(path, "inputs", name, model_inputs, "inputs")
        if variables[name].causality != "input":
            raise DataError(
                f"variable {name!r} is not an input of this FMU "
                f"(its causality is {variables[name].causality!r})",
                file=path,
                key="inputs",
                hint=_listing("the FMU's inputs", model_inputs),
            )
    model_outputs = [n for n, v in variables.items() if v.causality == "output"]
    for name in outputs.values():
        if name not in variables:
            raise _no_variable(path, "outputs", name, list(variables), "outputs", model_outputs)
    settable = [n for n, v in variables.items() if v.causality in ("parameter", "input", "local")]
    for name in parameters:
        if name not in variables:
            raise _no_variable(path, "parameters", name, settable, "parameters")


def _no_variable(
    path: str,
    key: str,
    name: str,
    pool: list[str],
    what: str,
    shown: list[str] | None = None,
) -> DataError:
    suggestion = did_you_mean(name, pool)
    return DataError(
        f"no variable {name!r} in this FMU",
        file=path,
        key=key,
        hint=suggestion or _listing(f"the FMU's {what}", shown if shown is not None else pool),
    )


def _listing(label: str, names: list[str]) -> str:
    if not names:
        return f"{label}: none"
    more = f" and {len(names) - 12} more" if len(names) > 12 else ""
    return f"{label}: " + ", ".join(repr(n) for n in names[:12]) + more


_FIELD_TYPES: dict[str, Any] = {
    "Boolean": np.bool_,
    "Integer": np.int32,
    "Enumeration": np.int32,
}


def _input_signals(
    path: str,
    reference: Record,
    inputs: Mapping[str, str],
    variables: Mapping[str, Any],
    start: float,
    stop: float,
) -> npt.NDArray[Any] | None:
    """The structured array fmpy reads inputs from, on the union of the channels' times."""
    if not inputs:
        return None
    channels: dict[str, Channel] = {}
    for variable, column in inputs.items():
        channel = reference.channel(column)
        first, last = float(channel.time[0]), float(channel.time[-1])
        # Half a sample of slack: a window ending on the last sample is covered.
        slack = 0.5 * float(np.median(np.diff(channel.time))) if channel.time.size > 1 else 0.0
        if first > start + slack or last < stop - slack:
            raise DataError(
                f"covers t={first:g}..{last:g} s but the FMU runs over {start:g}..{stop:g} s",
                file=reference.source,
                column=column,
                hint="set the simulation window inside the measurement",
            )
        inside = (channel.time >= start - slack) & (channel.time <= stop + slack)
        bad = np.flatnonzero(~np.isfinite(channel.values) & inside)
        if bad.size:
            raise DataError(
                f"has no value (NaN) at t={channel.time[bad[0]]:g} s, which the FMU would read "
                f"as input {variable!r}",
                file=reference.source,
                column=column,
                hint="fill the gap or shorten the simulation window",
            )
        channels[variable] = channel
    times = channels[next(iter(channels))].time
    for channel in channels.values():
        if channel.time is not times:
            times = np.union1d(times, channel.time)
    dtype = [("time", np.float64)] + [
        (name, _FIELD_TYPES.get(str(variables[name].type), np.float64)) for name in channels
    ]
    signals = np.zeros(times.size, dtype=dtype)
    signals["time"] = times
    for name, channel in channels.items():
        values = np.interp(times, channel.time, channel.values.astype(np.float64))
        field_type = signals.dtype[name]
        if field_type == np.bool_:
            signals[name] = values != 0
        elif field_type.kind == "i":
            signals[name] = np.round(values)
        else:
            signals[name] = values
    return signals


def _result_record(
    path: str,
    result: npt.NDArray[Any],
    outputs: Mapping[str, str],
    variables: Mapping[str, Any],
    description: Any,
    fmi_type: str,
) -> Record:
    time = np.asarray(result["time"], dtype=np.float64)
    # Model exchange records a sample before and after each event at the same instant; the
    # value after the event is the one that holds from then on.
    keep = np.append(np.diff(time) > 0, True)
    time = time[keep]
    events = int(keep.size - np.count_nonzero(keep)) if fmi_type == "ModelExchange" else None
    if time.size == 0 or np.any(np.diff(time) <= 0):
        raise DataError(
            "the simulation returned no usable time stamps",
            file=path,
            hint="check the FMU's start_time, stop_time and step_size",
        )
    channels = {}
    for signal, variable in outputs.items():
        values = np.asarray(result[variable])[keep]
        converted: npt.NDArray[np.floating] = (
            values if values.dtype in (np.float32, np.float64) else values.astype(np.float64)
        )
        unit = getattr(variables[variable], "unit", None)
        channels[signal] = Channel(time=time, values=converted, unit=unit or None)
    names = tuple(outputs)
    return Record(
        source=path,
        channels=channels,
        available=names,
        numeric=names,
        meta={
            "format": "fmu",
            "fmi_version": str(description.fmiVersion),
            "fmi_type": fmi_type,
            "model_name": str(description.modelName),
            "outputs": dict(outputs),
            # FMI 1 and 2 name the build by its GUID, FMI 3 by its instantiation token.
            "guid": str(
                getattr(description, "guid", None)
                or getattr(description, "instantiationToken", None)
                or ""
            ),
            **({"events": events} if events is not None else {}),
        },
    )

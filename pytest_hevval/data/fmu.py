"""Run an FMU (FMI 1/2/3, co-simulation or model exchange) on measured inputs, with fmpy.

The model is driven by channels of the reference record, so a validation compares the model
with the measurement it was fed. Every failure, from a damaged FMU file to an error inside the
model, becomes a :class:`~pytest_hevval.errors.DataError` naming the FMU file and what failed.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import DataError, MissingExtraError, did_you_mean
from ..files import check_input
from .record import Channel, Record
from .runtime import measure_call

__all__ = ["FMU_INTERFACES", "run_fmu", "tolerance_problem"]

FloatArray = npt.NDArray[np.float64]

# fmpy log status codes from "warning" upwards; the model's own words for what went wrong.
_LOG_WARNING = 1
_LOG_KEEP = 5
_STATUS_FATAL = 4

#: The FMI interfaces a spec can choose (``model: {interface: …}``), by fmpy's names.
FMU_INTERFACES: dict[str, str] = {
    "co-simulation": "CoSimulation",
    "model-exchange": "ModelExchange",
}


def run_fmu(
    fmu_path: str,
    reference: Record,
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    *,
    start_time: float,
    stop_time: float,
    step_size: float | None = None,
    parameters: Mapping[str, object] | None = None,
    interface: str | None = None,
    tolerance: float | None = None,
) -> Record:
    """Simulate ``fmu_path`` fed by ``reference`` channels; return the outputs as a record.

    Parameters
    ----------
    fmu_path
        The ``.fmu`` file (or a folder holding an extracted FMU).
    reference
        The measured record whose channels drive the FMU inputs.
    inputs
        FMU input variable → reference channel name. Real inputs are given on the union of
        the channels' time stamps and interpolated linearly by fmpy in between; integer and
        Boolean inputs hold each sample until the next. An event in the reference (two
        samples at one time stamp, ``Record.meta["events"]``) reaches fmpy as such.
    outputs
        Signal name to produce → FMU variable to record. An array variable gives one column
        per element, ``name[1]``, ``name[2]``, … (1-based, ``name[i,j]`` for a matrix); one
        element is named the same way (``y[2]``). Empty: every numeric output under its own
        name; String, Binary and Clock outputs are left out, each with the reason in
        ``Record.meta["unscored"]``, and reading one is an error that gives it.
    start_time, stop_time
        Simulation window in seconds; every input channel must cover it.
    step_size
        Communication step (co-simulation) and output interval. None lets fmpy choose from
        the FMU's default experiment.
    parameters
        Start values for FMU variables (parameters or initial states), each converted to the
        variable's declared type (a number, a whole number, true/false or text).
    interface
        ``"co-simulation"`` or ``"model-exchange"``; None: co-simulation when the FMU has it.
    tolerance
        Relative tolerance: of fmpy's CVode solver for model exchange, passed to the FMU
        for co-simulation. None: the FMU's default experiment's, else fmpy's.

    Returns
    -------
    Record
        One channel per ``outputs`` key (per element of an array), all sharing the
        simulation's time stamps.
    """
    fmpy = _import_fmpy()
    fmu_path = os.fspath(fmu_path)
    _check_window(fmu_path, start_time, stop_time, step_size)
    _check_tolerance(fmu_path, tolerance)
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
    fmi_type = _fmi_type(fmu_path, description, interface)
    recorded, unscored = _check_variables(fmu_path, variables, inputs, outputs, parameters or {})
    fmi_version = str(description.fmiVersion)
    start_values = _start_values(fmu_path, variables, parameters or {}, fmi_version)
    signals = _input_signals(reference, inputs, variables, fmi_version, start_time, stop_time)

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
            held = _discrete_inputs_held(instance, variables, signals, fmi_version, fmi_type)

            def step_finished(time: float, recorder: Any) -> bool:
                count_step()
                return held(time, recorder) if held is not None else True

            result, cost = measure_call(
                lambda: fmpy.simulate_fmu(
                    unzipdir,
                    validate=False,
                    start_time=start_time,
                    stop_time=stop_time,
                    step_size=step_size,
                    output_interval=step_size,
                    fmi_type=fmi_type,
                    relative_tolerance=tolerance,
                    start_values=start_values,
                    input=signals,
                    output=list(dict.fromkeys(ref.variable for ref in recorded.values())),
                    model_description=description,
                    fmu_instance=instance,
                    step_finished=step_finished,
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

    record = _result_record(fmu_path, result, recorded, variables, description, fmi_type)
    record.meta["unscored"] = unscored
    record.meta["cost"] = cost
    record.meta["steps"] = steps
    return record


def _discrete_inputs_held(
    instance: Any,
    variables: Mapping[str, Any],
    signals: npt.NDArray[Any] | None,
    fmi_version: str,
    fmi_type: str,
) -> Callable[[float, Any], bool] | None:
    """After each co-simulation step, set the integer and Boolean inputs for the next one.

    fmpy before 0.3.23 (the last that runs on numpy 1.x) sets a co-simulation's discrete
    inputs once, at the start, and holds them there for the whole run. Later versions set
    them before each step by the same rule (the last sample at or before the step's start),
    after this, so their values are the ones the step reads.
    """
    if fmi_type != "CoSimulation" or signals is None:
        return None
    names = [n for n in signals.dtype.names or () if signals.dtype[n].kind in "biu"]
    if not names:
        return None
    times = signals["time"]
    fmi3 = not fmi_version.startswith(("1.", "2."))
    setters = [
        (getattr(instance, _setter(variables[name], fmi3)), variables[name].valueReference, name)
        for name in names
    ]

    def apply(time: float, recorder: Any) -> bool:
        # fmpy's time is a sum of steps: a sample at the step's start counts within rounding.
        index = int(np.searchsorted(times, time + 1e-9 * max(1.0, abs(time)), side="right")) - 1
        for setter, reference, name in setters:
            setter([reference], [signals[name][max(index, 0)].item()])
        return True  # go on

    return apply


def _setter(variable: Any, fmi3: bool) -> str:
    """The name of fmpy's setter for a discrete variable's type."""
    kind = str(variable.type)
    if kind == "Enumeration":
        return "setInt64" if fmi3 else "setInteger"
    return f"set{kind}"


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


def tolerance_problem(tolerance: float) -> str | None:
    """What is wrong with ``tolerance`` as a relative tolerance; None when nothing is."""
    if math.isfinite(tolerance) and 0 < tolerance < 1:
        return None
    return "must be a relative tolerance, greater than 0 and less than 1 (such as 1e-6)"


def _check_tolerance(path: str, tolerance: float | None) -> None:
    problem = None if tolerance is None else tolerance_problem(tolerance)
    if problem is not None:
        raise DataError(f"tolerance={tolerance} {problem}", file=path, key="tolerance")


def _fmi_type(path: str, description: Any, interface: str | None) -> str:
    """fmpy's name of the interface to run: the one asked for, else co-simulation if offered."""
    offered = [
        name
        for name, fmi_type in FMU_INTERFACES.items()
        if getattr(description, fmi_type[0].lower() + fmi_type[1:], None) is not None
    ]
    if interface is None:
        if not offered:
            raise DataError(
                "this FMU offers neither co-simulation nor model exchange",
                file=path,
                hint="export the FMU with a co-simulation or model-exchange interface",
            )
        return FMU_INTERFACES[offered[0]]
    if interface not in FMU_INTERFACES:
        raise DataError(
            f"no interface {interface!r}",
            file=path,
            key="interface",
            hint="choose " + " or ".join(FMU_INTERFACES),
        )
    if interface not in offered:
        raise DataError(
            f"this FMU has no {interface} interface",
            file=path,
            key="interface",
            hint=_listing("it offers", offered) + "; choose one of those or remove `interface:`",
        )
    return FMU_INTERFACES[interface]


@dataclass(frozen=True)
class _Output:
    """One FMU variable to record, or one element of an array variable (1-based index)."""

    variable: str
    index: tuple[int, ...] | None = None

    @property
    def name(self) -> str:
        return self.variable if self.index is None else _element_name(self.variable, self.index)


def _element_name(variable: str, index: tuple[int, ...]) -> str:
    """``y[2]``, ``m[1,2]``: an array element as FMI and Modelica name it, 1-based."""
    return f"{variable}[{','.join(map(str, index))}]"


_ELEMENT = re.compile(r"(?P<name>.+)\[(?P<index>\s*\d+\s*(?:,\s*\d+\s*)*)\]")
#: Variable types whose values cannot be scored as numbers.
_NOT_NUMBERS = {"String": "text", "Binary": "bytes", "Clock": "clock ticks"}


def _output_ref(variables: Mapping[str, Any], name: str) -> _Output | None:
    """The variable (or array element) ``name`` names; None when the FMU has no such one.

    A variable whose own name has brackets (FMI 2 exports name array elements so) wins over
    an element of an array variable.
    """
    if name in variables:
        return _Output(name)
    match = _ELEMENT.fullmatch(name)
    if match is None or match["name"] not in variables:
        return None
    return _Output(match["name"], tuple(int(i) for i in match["index"].split(",")))


def _shape(variable: Any) -> tuple[int, ...]:
    """An array variable's dimensions (``()`` for a scalar), as fmpy read them."""
    return tuple(int(n) for n in getattr(variable, "shape", None) or ())


def _check_element(path: str, ref: _Output, shape: tuple[int, ...]) -> None:
    if ref.index is None:
        return
    if len(ref.index) == len(shape) and all(
        1 <= i <= n for i, n in zip(ref.index, shape, strict=True)
    ):
        return
    if not shape:
        problem, hint = f"{ref.variable!r} is no array", f"name it as {ref.variable!r}"
    else:
        first = _element_name(ref.variable, (1,) * len(shape))
        size = "×".join(map(str, shape))
        problem = f"{ref.name!r} is outside the array {ref.variable!r} ({size})"
        hint = f"its elements are {first} … {_element_name(ref.variable, shape)} (from 1)"
    raise DataError(problem, file=path, key="outputs", hint=hint)


def _check_variables(
    path: str,
    variables: Mapping[str, Any],
    inputs: Mapping[str, str],
    outputs: Mapping[str, str],
    parameters: Mapping[str, object],
) -> tuple[dict[str, _Output], dict[str, str]]:
    """Check every name against the FMU; the variable (or element) each output records, and
    the outputs left out because they hold no numbers (with the reason)."""
    model_inputs = [n for n, v in variables.items() if v.causality == "input"]
    for name in inputs:
        if name not in variables:
            raise _no_variable(path, "inputs", name, model_inputs, "inputs")
        variable = variables[name]
        if variable.causality != "input":
            raise DataError(
                f"variable {name!r} is not an input of this FMU "
                f"(its causality is {variable.causality!r})",
                file=path,
                key="inputs",
                hint=_listing("the FMU's inputs", model_inputs),
            )
        if _shape(variable) or str(variable.type) in _NOT_NUMBERS:
            raise DataError(
                f"input {name!r} is {_kind(variable)}, which one measured channel cannot drive",
                file=path,
                key="inputs",
                hint=f"remove {name!r} from the inputs; the FMU then uses its start value",
            )
    found = _recorded_outputs(path, variables, outputs)
    settable = [n for n, v in variables.items() if v.causality in ("parameter", "input", "local")]
    for name in parameters:
        if name not in variables:
            raise _no_variable(path, "parameters", name, settable, "parameters")
    return found


def _recorded_outputs(
    path: str, variables: Mapping[str, Any], outputs: Mapping[str, str]
) -> tuple[dict[str, _Output], dict[str, str]]:
    """What each output column records; without ``outputs``, every numeric output under its
    own name, and the others left out with the reason."""
    model_outputs = [n for n, v in variables.items() if v.causality == "output"]
    numeric = [n for n in model_outputs if str(variables[n].type) not in _NOT_NUMBERS]
    if not outputs:
        unscored = {
            name: _not_numbers(name, variables[name])
            for name in model_outputs
            if name not in numeric
        }
        return {name: _Output(name) for name in numeric}, unscored
    recorded: dict[str, _Output] = {}
    for signal, name in outputs.items():
        ref = _output_ref(variables, name)
        if ref is None:
            raise _no_variable(path, "outputs", name, list(variables), "outputs", model_outputs)
        variable = variables[ref.variable]
        if str(variable.type) in _NOT_NUMBERS:
            raise DataError(
                _not_numbers(name, variable),
                file=path,
                key="outputs",
                hint=f"remove {signal!r} from the outputs; "
                + _listing("the FMU's numeric outputs", numeric),
            )
        _check_element(path, ref, _shape(variable))
        recorded[signal] = ref
    return recorded, {}


def _not_numbers(name: str, variable: Any) -> str:
    kind = str(variable.type)
    return (
        f"output {name!r} is a {kind} variable: it holds {_NOT_NUMBERS[kind]}, not numbers, "
        "and cannot be scored"
    )


def _kind(variable: Any) -> str:
    shape = _shape(variable)
    if shape:
        return f"an array of {'×'.join(map(str, shape))} {variable.type} values"
    return f"a {variable.type} variable"


_INTEGER_TYPES: dict[str, Any] = {
    "Integer": np.int32,
    "Int8": np.int8,
    "UInt8": np.uint8,
    "Int16": np.int16,
    "UInt16": np.uint16,
    "Int32": np.int32,
    "UInt32": np.uint32,
    "Int64": np.int64,
    "UInt64": np.uint64,
}
_REAL_TYPES = ("Real", "Float32", "Float64")


def _integer_type(variable: Any, fmi_version: str) -> Any:
    """The numpy type of an integer-valued variable (FMI 3 enumerations are Int64), or None."""
    kind = str(variable.type)
    if kind == "Enumeration":
        return np.int32 if fmi_version.startswith(("1.", "2.")) else np.int64
    return _INTEGER_TYPES.get(kind)


def _start_values(
    path: str, variables: Mapping[str, Any], parameters: Mapping[str, object], fmi_version: str
) -> dict[str, Any]:
    """Each parameter converted to its variable's declared type, or an error naming it."""
    converted: dict[str, Any] = {}
    for name, value in parameters.items():
        variable = variables[name]
        shape = _shape(variable)
        if shape:
            size = int(np.prod(shape))
            if not isinstance(value, list | tuple) or len(value) != size:
                raise _bad_parameter(path, name, variable, value, f"a list of {size} values")
            converted[name] = [_start_value(path, name, variable, v, fmi_version) for v in value]
        else:
            converted[name] = _start_value(path, name, variable, value, fmi_version)
    return converted


def _start_value(path: str, name: str, variable: Any, value: object, fmi_version: str) -> Any:
    kind = str(variable.type)
    if kind not in ("String", "Boolean") and isinstance(value, str):
        # YAML 1.1 reads 1e-6 (no dot) as text; as the spec's own numbers, it is a number.
        value = _number(value)
    if kind in _REAL_TYPES:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
        raise _bad_parameter(path, name, variable, value, "a number")
    if kind == "Boolean":
        if isinstance(value, bool):
            return value
        raise _bad_parameter(path, name, variable, value, "true or false")
    if kind == "String":
        if isinstance(value, str):
            return value
        quoted = f"in YAML, quote a value that reads as a number: '{value}'"
        raise _bad_parameter(path, name, variable, value, "text", f"give {name!r} text ({quoted})")
    integer = _integer_type(variable, fmi_version)
    if integer is None:
        raise DataError(
            f"parameter {name!r} is {_kind(variable)}, which a spec cannot set",
            file=path,
            key="parameters",
            hint=f"remove {name!r} from the parameters",
        )
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if not isinstance(value, int) or isinstance(value, bool):
        raise _bad_parameter(path, name, variable, value, "a whole number")
    limits = np.iinfo(integer)
    if not limits.min <= value <= limits.max:
        raise _bad_parameter(
            path, name, variable, value, f"a whole number from {limits.min} to {limits.max}"
        )
    return value


def _number(text: str) -> object:
    """``text`` as an int or a float if it spells one, else ``text`` itself."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _bad_parameter(
    path: str, name: str, variable: Any, value: object, wanted: str, hint: str | None = None
) -> DataError:
    return DataError(
        f"parameter {name!r} is {_kind(variable)}; {value!r} is not {wanted}",
        file=path,
        key="parameters",
        hint=hint or f"give {name!r} {wanted}",
    )


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


#: Whole numbers beyond this are not all representable in float64, the type channels hold.
_EXACT_INTEGER = 2**53


def _input_signals(
    reference: Record,
    inputs: Mapping[str, str],
    variables: Mapping[str, Any],
    fmi_version: str,
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
        window = (channel.time >= start - slack) & (channel.time <= stop + slack)
        bad = np.flatnonzero(~np.isfinite(channel.values) & window)
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
    # The window's own ends first and last: fmpy holds the first row from the start (at a
    # sample on the start it would read an integer input's sample before, at initialisation).
    times = np.concatenate(([start], times[(times > start) & (times < stop)], [stop]))
    dtype = [("time", np.float64)] + [
        (name, _field_type(variables[name], fmi_version)) for name in channels
    ]
    signals = np.zeros(times.size, dtype=dtype)
    for name, channel in channels.items():
        field_type = signals.dtype[name]
        if field_type.kind in "biu":
            # Discrete inputs hold each sample until the next, as fmpy holds them.
            held = channel.values[_previous(channel.time, times)].astype(np.float64)
            if field_type.kind == "b":
                signals[name] = held != 0
            else:
                signals[name] = _exact_integers(
                    reference.source, inputs[name], name, variables[name], field_type, held, times
                )
        else:
            signals[name] = np.interp(times, channel.time, channel.values.astype(np.float64))
    signals["time"] = _with_events(reference, times)
    return _discrete_changes_as_events(signals)


def _discrete_changes_as_events(signals: npt.NDArray[Any]) -> npt.NDArray[Any]:
    """``signals`` with each change of an integer or Boolean input as an event: a row before
    it (the old value) and one after it (the new) at the change's time stamp.

    Between two rows fmpy 0.3.22 gives a discrete input the later row's value at an event of
    model exchange; with the old value held at the change's own time stamp it gives the value
    that holds there, as later versions do.
    """
    names = [n for n in signals.dtype.names or () if signals.dtype[n].kind in "biu"]
    if not names:
        return signals
    changes = np.zeros(signals.size, dtype=bool)
    for name in names:
        changes[1:] |= signals[name][1:] != signals[name][:-1]
    # A change that is an event of the reference has its row before already.
    changes[1:] &= np.diff(signals["time"]) > 0
    at = np.flatnonzero(changes)
    if not at.size:
        return signals
    before = signals[at]
    for name in names:
        before[name] = signals[name][at - 1]
    return np.insert(signals, at, before)


def _field_type(variable: Any, fmi_version: str) -> Any:
    if str(variable.type) == "Boolean":
        return np.bool_
    if str(variable.type) == "Float32":
        return np.float32
    return _integer_type(variable, fmi_version) or np.float64


def _previous(time: FloatArray, at: FloatArray) -> npt.NDArray[np.intp]:
    """Index of the last sample at or before each of ``at`` (the first, for times before it)."""
    return np.maximum(np.searchsorted(time, at, side="right") - 1, 0)


def _exact_integers(
    source: str,
    column: str,
    name: str,
    variable: Any,
    integer: np.dtype[Any],
    values: FloatArray,
    times: FloatArray,
) -> npt.NDArray[np.integer]:
    """``values`` as the input's integer type, or an error at the first one it cannot hold."""
    limits = np.iinfo(integer)
    with np.errstate(invalid="ignore"):
        inexact = np.abs(values) > _EXACT_INTEGER
        fraction = values != np.round(values)
        outside = (values < float(limits.min)) | (values > float(limits.max))
    for wrong, problem, hint in (
        (
            inexact,
            "which is beyond 2**53, the largest whole number float64 (the type channels are "
            "read as) holds exactly: the file's value may have been rounded",
            "keep the channel's values within ±2**53 (9007199254740992), for example by "
            "subtracting an offset",
        ),
        (fraction, "which is no whole number", "feed the input a channel of whole numbers"),
        (
            outside,
            f"outside its range {limits.min}..{limits.max}",
            "feed the input a channel within that range",
        ),
    ):
        bad = np.flatnonzero(wrong)
        if bad.size:
            i = int(bad[0])
            raise DataError(
                f"holds {values[i]:.17g} at t={times[i]:g} s for the FMU's {variable.type} input "
                f"{name!r}, {problem}",
                file=source,
                column=column,
                hint=hint,
            )
    return values.astype(integer)


def _with_events(reference: Record, times: FloatArray) -> FloatArray:
    """The input's time stamps with each event's two samples at the event's one time stamp.

    A reader keeps an event's sample before it one float64 step earlier (so time increases
    strictly for scoring) and lists the event times in ``meta["events"]``; fmpy reads two
    rows at one time stamp as an event, with the values before and after it.
    """
    events = reference.meta.get("events")
    if events is None or len(events) == 0:
        return times
    before = np.nextafter(np.asarray(events, dtype=np.float64), -np.inf)
    at = np.isin(times, before)
    if not at.any():
        return times
    stamped: FloatArray = times.copy()
    stamped[at] = np.nextafter(stamped[at], np.inf)
    return stamped


def _result_record(
    path: str,
    result: npt.NDArray[Any],
    outputs: Mapping[str, _Output],
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
    for signal, ref in outputs.items():
        recorded = np.asarray(result[ref.variable])[keep]
        unit = getattr(variables[ref.variable], "unit", None) or None
        shape = recorded.shape[1:]
        # One column per element, in FMI's row-major order.
        flat = recorded.reshape(recorded.shape[0], -1)
        if ref.index is not None:
            _check_element(path, ref, shape)
            element = np.ravel_multi_index(tuple(i - 1 for i in ref.index), shape)
            channels[signal] = Channel(time, _as_floats(flat[:, element]), unit)
            continue
        for column, element in enumerate(np.ndindex(*shape)):
            # An array gives one column per element, named with 1-based indices as FMI does.
            name = _element_name(signal, tuple(i + 1 for i in element)) if shape else signal
            channels[name] = Channel(time, _as_floats(flat[:, column]), unit)
    names = tuple(channels)
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
            "outputs": {signal: ref.name for signal, ref in outputs.items()},
            # FMI 1 and 2 name the build by its GUID, FMI 3 by its instantiation token.
            "guid": str(
                getattr(description, "guid", None)
                or getattr(description, "instantiationToken", None)
                or ""
            ),
            **({"events": events} if events is not None else {}),
        },
    )


def _as_floats(values: npt.NDArray[Any]) -> npt.NDArray[np.floating]:
    """Recorded values as the floats channels hold (float32 stays float32)."""
    if values.dtype in (np.float32, np.float64):
        return values
    return values.astype(np.float64)

"""The FMU runner, on FMUs built here with pythonfmu (co-simulation, Python inside)."""

from __future__ import annotations

import os
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from pytest_hevval.data.fmu import run_fmu
from pytest_hevval.data.record import Channel, Record
from pytest_hevval.errors import DataError, MissingExtraError

pytest.importorskip("fmpy")

GAIN = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Gain(Fmi2Slave):
    """y = k*u + c, with a second output z = u*u."""

    description = "gain block"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 0.0
        self.k = 2.0
        self.c = 0.5
        self.y = 0.0
        self.z = 0.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        for name in ("k", "c"):
            self.register_variable(
                Real(name, causality=Fmi2Causality.parameter,
                     variability=Fmi2Variability.tunable)
            )
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        self.register_variable(Real("z", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.y = self.k * self.u + self.c
        self.z = self.u * self.u
        return True
'''

FAILING = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class Failing(Fmi2Slave):
    """Breaks down after half a second, as a diverging model would."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.y = 0.0
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        if current_time > 0.5:
            raise RuntimeError("solver diverged at t > 0.5")
        self.y = current_time
        return True
'''

COUNTER = '''
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer


class Counter(Fmi2Slave):
    """Echoes an Integer and a Boolean input (FMI 2 discrete inputs)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.n = 0
        self.on = False
        self.n_out = 0
        self.on_out = False
        for name, kind in (("n", Integer), ("on", Boolean)):
            self.register_variable(
                kind(name, causality=Fmi2Causality.input, variability=Fmi2Variability.discrete)
            )
            self.register_variable(
                kind(
                    name + "_out",
                    causality=Fmi2Causality.output,
                    variability=Fmi2Variability.discrete,
                )
            )

    def do_step(self, current_time, step_size):
        self.n_out = self.n
        self.on_out = self.on
        return True
'''


def _build(tmp: Path, name: str, source: str) -> str:
    builder = pytest.importorskip("pythonfmu.builder")
    script = tmp / f"{name}.py"
    script.write_text(textwrap.dedent(source))
    return str(builder.FmuBuilder.build_FMU(script, dest=tmp))


@pytest.fixture(scope="module")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    tmp = tmp_path_factory.mktemp("fmus")
    return {
        "gain": _build(tmp, "Gain", GAIN),
        "failing": _build(tmp, "Failing", FAILING),
        "counter": _build(tmp, "Counter", COUNTER),
    }


def _reference() -> Record:
    t = np.arange(0, 2.0001, 0.01)
    slow_t = np.arange(0, 2.0001, 0.1)
    return Record(
        source="measured.csv",
        channels={
            "throttle": Channel(time=t, values=np.sin(2 * t)),
            "slow": Channel(time=slow_t, values=slow_t * 0.5),
            "gappy": Channel(time=t, values=np.where(t > 1.0, np.nan, t)),
        },
    )


def test_gain_fmu_follows_its_input(fmus: dict[str, str]) -> None:
    record = run_fmu(
        fmus["gain"],
        _reference(),
        inputs={"u": "throttle"},
        outputs={"y_sim": "y", "z_sim": "z"},
        start_time=0.0,
        stop_time=2.0,
        step_size=0.01,
        parameters={"k": 3.0, "c": -1.0},
    )
    assert list(record.channels) == ["y_sim", "z_sim"]
    y = record.channels["y_sim"]
    assert y.time.dtype == np.float64
    np.testing.assert_allclose(y.time, np.arange(201) * 0.01, atol=1e-9)
    assert np.all(np.diff(y.time) > 0)
    # A co-simulation step from t to t+h reads u(t): outputs trail the input by one step.
    u_before = np.sin(2 * y.time[:-1])
    np.testing.assert_allclose(y.values[1:], 3.0 * u_before - 1.0, atol=1e-9)
    np.testing.assert_allclose(record.channels["z_sim"].values[1:], u_before**2, atol=1e-9)
    assert record.source == fmus["gain"]
    assert record.meta["fmi_type"] == "CoSimulation"
    assert record.meta["model_name"] == "Gain"


def test_default_parameters_and_union_of_times(fmus: dict[str, str]) -> None:
    record = run_fmu(
        fmus["gain"],
        _reference(),
        inputs={"u": "slow"},
        outputs={"y": "y"},
        start_time=0.5,
        stop_time=1.5,
        step_size=0.05,
    )
    y = record.channels["y"]
    np.testing.assert_allclose(y.time[0], 0.5)
    np.testing.assert_allclose(y.time[-1], 1.5)
    # k=2, c=0.5 from the model; the 10 Hz input is interpolated linearly between samples.
    np.testing.assert_allclose(y.values[1:], 2.0 * (0.5 * y.time[:-1]) + 0.5, atol=1e-9)


def test_no_inputs_runs_free(fmus: dict[str, str]) -> None:
    record = run_fmu(
        fmus["gain"], _reference(), {}, {"y": "y"}, start_time=0.0, stop_time=1.0, step_size=0.1
    )
    np.testing.assert_allclose(record.channels["y"].values[1:], 0.5)


def test_model_failure_is_a_data_error(fmus: dict[str, str]) -> None:
    with pytest.raises(DataError) as info:
        run_fmu(
            fmus["failing"],
            _reference(),
            {},
            {"y": "y"},
            start_time=0.0,
            stop_time=1.0,
            step_size=0.1,
        )
    message = str(info.value)
    assert message.startswith(f"{fmus['failing']}: the model failed during the simulation (")
    assert "fmpy.simulate_fmu with debug_logging=True" in message
    assert info.value.file == fmus["failing"]


@pytest.mark.parametrize(
    ("kwargs", "expected"),
    [
        (
            {"inputs": {"uu": "throttle"}},
            "{fmu}: inputs: no variable 'uu' in this FMU; did you mean 'u'?",
        ),
        (
            {"inputs": {"y": "throttle"}},
            "{fmu}: inputs: variable 'y' is not an input of this FMU (its causality is "
            "'output'); the FMU's inputs: 'u'",
        ),
        (
            {"outputs": {"out": "speed"}},
            "{fmu}: outputs: no variable 'speed' in this FMU; the FMU's outputs: 'y', 'z'",
        ),
        (
            {"parameters": {"kk": 1.0}},
            "{fmu}: parameters: no variable 'kk' in this FMU; did you mean 'k'?",
        ),
        (
            {"inputs": {"u": "throtle"}},
            "measured.csv: column 'throtle': no such column in this file; did you mean 'throttle'?",
        ),
        (
            {"stop_time": 3.0},
            "measured.csv: column 'throttle': covers t=0..2 s but the FMU runs over 0..3 s; set "
            "the simulation window inside the measurement",
        ),
        (
            {"inputs": {"u": "gappy"}},
            "measured.csv: column 'gappy': has no value (NaN) at t=1.01 s, which the FMU would "
            "read as input 'u'; fill the gap or shorten the simulation window",
        ),
        (
            {"stop_time": 0.0},
            "{fmu}: the simulation window is empty or not finite (start_time=0.0, "
            "stop_time=0.0); set stop_time after start_time",
        ),
        (
            {"tolerance": 2.0},
            "{fmu}: tolerance: tolerance=2.0 must be a relative tolerance, greater than 0 and "
            "less than 1 (such as 1e-6)",
        ),
        (
            {"interface": "cs"},
            "{fmu}: interface: no interface 'cs'; choose co-simulation or model-exchange",
        ),
        (
            {"step_size": -0.1},
            "{fmu}: step_size: step_size=-0.1 does not fit the window 0.0..2.0 s; use a "
            "positive step smaller than the window",
        ),
    ],
)
def test_bad_use_is_explained(
    fmus: dict[str, str], kwargs: dict[str, object], expected: str
) -> None:
    args: dict[str, object] = {
        "inputs": {"u": "throttle"},
        "outputs": {"y": "y"},
        "start_time": 0.0,
        "stop_time": 2.0,
        "step_size": 0.1,
    }
    args.update(kwargs)
    with pytest.raises(DataError) as info:
        run_fmu(fmus["gain"], _reference(), **args)  # type: ignore[arg-type]
    assert str(info.value) == expected.format(fmu=fmus["gain"])


def test_integer_and_boolean_inputs_hold_each_sample(fmus: dict[str, str]) -> None:
    # Sampled at 10 Hz, run at 100 Hz: between samples the FMU gets the last one, never a
    # value in between, on every fmpy (0.3.22 held them at the first for the whole run).
    slow = np.round(np.arange(0, 2.0001, 0.1), 10)
    counts = np.arange(slow.size) * 1000.0 - 7.0
    switch = (np.arange(slow.size) % 3 == 0).astype(float)
    reference = Record(
        source="measured.csv",
        channels={"count": Channel(slow, counts), "switch": Channel(slow, switch)},
    )
    record = run_fmu(
        fmus["counter"],
        reference,
        inputs={"n": "count", "on": "switch"},
        outputs={"n": "n_out", "on": "on_out"},
        start_time=0.0,
        stop_time=2.0,
        step_size=0.01,
    )
    time = record.channels["n"].time
    # The output at t + h echoes the input read at the step's start t.
    held = np.searchsorted(slow, time[:-1] + 1e-9, side="right") - 1
    np.testing.assert_array_equal(record.channels["n"].values[1:], counts[held])
    np.testing.assert_array_equal(record.channels["on"].values[1:], switch[held])


def test_an_integer_beyond_its_type_is_refused(fmus: dict[str, str]) -> None:
    t = np.arange(0, 2.0001, 0.1)
    reference = Record(
        source="measured.csv", channels={"count": Channel(t, np.full(t.size, 2.0**31))}
    )
    with pytest.raises(DataError) as info:
        run_fmu(
            fmus["counter"],
            reference,
            {"n": "count"},
            {"n": "n_out"},
            start_time=0.0,
            stop_time=1.0,
        )
    assert str(info.value) == (
        "measured.csv: column 'count': holds 2147483648 at t=0 s for the FMU's Integer input "
        "'n', outside its range -2147483648..2147483647; feed the input a channel within that "
        "range"
    )


def test_an_interface_the_fmu_lacks_is_named(fmus: dict[str, str]) -> None:
    with pytest.raises(DataError) as info:
        run_fmu(
            fmus["gain"],
            _reference(),
            {},
            {"y": "y"},
            start_time=0.0,
            stop_time=1.0,
            interface="model-exchange",
        )
    assert str(info.value) == (
        f"{fmus['gain']}: interface: this FMU has no model-exchange interface; it offers: "
        "'co-simulation'; choose one of those or remove `interface:`"
    )


def test_missing_and_damaged_fmu_files(tmp_path: Path) -> None:
    missing = str(tmp_path / "nope.fmu")
    with pytest.raises(DataError) as info:
        run_fmu(missing, _reference(), {}, {"y": "y"}, start_time=0.0, stop_time=1.0)
    assert str(info.value) == f"{missing}: FMU file not found; check the path"

    damaged = tmp_path / "broken.fmu"
    damaged.write_bytes(b"PK\x03\x04 this is not a zip archive")
    with pytest.raises(DataError) as info:
        run_fmu(str(damaged), _reference(), {}, {"y": "y"}, start_time=0.0, stop_time=1.0)
    message = str(info.value)
    assert message.startswith(f"{damaged}: cannot read the FMU's model description (")
    assert message.endswith(
        "check that this is an FMU (a zip with modelDescription.xml) and not damaged"
    )
    assert sorted(os.listdir(tmp_path)) == ["broken.fmu"]


def test_missing_fmpy_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "fmpy", None)
    with pytest.raises(MissingExtraError) as info:
        run_fmu("model.fmu", _reference(), {}, {"y": "y"}, start_time=0.0, stop_time=1.0)
    assert "pip install 'pytest-hevval[fmu]'" in str(info.value)

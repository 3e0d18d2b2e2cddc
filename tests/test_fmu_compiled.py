"""The FMU runner on FMUs compiled from C here: an FMI 3.0 one (tests/fmus/probe3.c) for array
outputs, 64-bit integer inputs, String parameters and outputs, the choice of interface, the
start time and tolerance, and inputs with events, through ``run_fmu`` and through
``pytest --hevval``; an FMI 2.0 one (probe2.c) for the same run settings on FMI 2."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pytest_hevval.data.fmu import run_fmu
from pytest_hevval.data.readers import read_record
from pytest_hevval.data.record import Channel, Record, SourceOptions
from pytest_hevval.errors import DataError, SpecError
from pytest_hevval.spec.load import load_spec
from tests.compiled_fmus import build_fmu

fmpy = pytest.importorskip("fmpy")

pytest_plugins = ["pytester"]

#: Int64's and UInt64's largest values, as a CSV reader hands them over (float64).
INT64_MAX = 2**63 - 1
UINT64_MAX = 2**64 - 1


@pytest.fixture(scope="session")
def probe(tmp_path_factory: pytest.TempPathFactory) -> str:
    return build_fmu("probe3", "3.0", tmp_path_factory.mktemp("compiled-fmus"))


@pytest.fixture(scope="session")
def probe2(tmp_path_factory: pytest.TempPathFactory) -> str:
    return build_fmu("probe2", "2.0", tmp_path_factory.mktemp("compiled-fmus"))


def _reference(**columns: tuple[np.ndarray, np.ndarray]) -> Record:
    return Record(
        source="measured.csv",
        channels={name: Channel(time=t, values=v) for name, (t, v) in columns.items()},
    )


TIME = np.round(np.arange(0, 1.0001, 0.01), 10)
STILL = _reference(zero=(TIME, np.zeros(TIME.size)))


def _run(probe: str, reference: Record = STILL, **kwargs: Any) -> Record:
    args: dict[str, Any] = {
        "inputs": {},
        "outputs": {"y": "y"},
        "start_time": 0.0,
        "stop_time": 1.0,
        "step_size": 0.01,
    }
    args.update(kwargs)
    return run_fmu(probe, reference, **args)


def _error(probe: str, reference: Record = STILL, **kwargs: Any) -> str:
    with pytest.raises(DataError) as info:
        _run(probe, reference, **kwargs)
    return str(info.value).replace(probe, "probe3.fmu")


#: The columns of the array y (3) and the matrix m (2×2), in FMI's order.
ELEMENTS = ["y[1]", "y[2]", "y[3]", "m[1,1]", "m[1,2]", "m[2,1]", "m[2,2]"]


def test_array_outputs_become_one_column_per_element(probe: str) -> None:
    record = _run(
        probe,
        outputs={"y": "y", "m": "m", "second": "y[2]", "corner": "m[2,1]"},
        parameters={"k": 0.5},
    )
    assert list(record.channels) == [*ELEMENTS, "second", "corner"]
    # Co-simulation: the model steps x exactly, x = exp(-k t).
    x = np.exp(-0.5 * TIME)
    for i in (1, 2, 3):
        np.testing.assert_allclose(record.channels[f"y[{i}]"].values, i * x, rtol=1e-12)
    for i, j in ((1, 1), (1, 2), (2, 1), (2, 2)):
        np.testing.assert_allclose(
            record.channels[f"m[{i},{j}]"].values, (10 * i + j) * x, rtol=1e-12
        )
    np.testing.assert_array_equal(record.channels["second"].values, record.channels["y[2]"].values)
    np.testing.assert_array_equal(
        record.channels["corner"].values, record.channels["m[2,1]"].values
    )
    assert record.meta["outputs"] == {"y": "y", "m": "m", "second": "y[2]", "corner": "m[2,1]"}


@pytest.mark.parametrize(
    ("output", "expected"),
    [
        ("y[4]", "'y[4]' is outside the array 'y' (3); its elements are y[1] … y[3] (from 1)"),
        ("y[0]", "'y[0]' is outside the array 'y' (3); its elements are y[1] … y[3] (from 1)"),
        (
            "m[3]",
            "'m[3]' is outside the array 'm' (2×2); its elements are m[1,1] … m[2,2] (from 1)",
        ),
        ("k[1]", "'k' is no array; name it as 'k'"),
        (
            "z[1]",
            "no variable 'z[1]' in this FMU; the FMU's outputs: 'i64_out', 'u64_out', 'y', "
            "'m', 'label_out', 'label_length', 'tol_seen', 'start_seen', 'blob', 'u_out', "
            "'offset_sum'",
        ),
    ],
)
def test_array_elements_out_of_range_are_explained(probe: str, output: str, expected: str) -> None:
    assert _error(probe, outputs={"s": output}) == f"probe3.fmu: outputs: {expected}"


def test_64_bit_integer_inputs_arrive_exactly_and_are_held(probe: str) -> None:
    # The largest whole numbers float64 (the channels' type) holds exactly, on a 10 Hz
    # channel, fed beside a 100 Hz real input: between its samples the integer input holds
    # the last one, as a measured integer does, never a value in between.
    slow = np.round(np.arange(0, 1.0001, 0.1), 10)
    big = float(2**53 - 1)
    signed = np.where(np.arange(slow.size) % 2 == 0, big, -big)
    unsigned = np.arange(slow.size) * 9e14 + 1
    reference = _reference(signed=(slow, signed), unsigned=(slow, unsigned), u=(TIME, np.sin(TIME)))
    record = _run(
        probe,
        reference,
        inputs={"i64": "signed", "u64": "unsigned", "u": "u"},
        outputs={"i": "i64_out", "n": "u64_out"},
    )
    # A co-simulation step reads the inputs at its start: outputs trail them by one step.
    held = np.searchsorted(slow, TIME[:-1] + 1e-9, side="right") - 1
    np.testing.assert_array_equal(record.channels["i"].values[1:], signed[held])
    np.testing.assert_array_equal(record.channels["n"].values[1:], unsigned[held])


@pytest.mark.parametrize(
    ("variable", "value", "expected"),
    [
        (
            "i64",
            float(INT64_MAX),
            "holds 9.2233720368547758e+18 at t=0 s for the FMU's Int64 input 'i64', which is "
            "beyond 2**53, the largest whole number float64 (the type channels are read as) "
            "holds exactly: the file's value may have been rounded; keep the channel's values "
            "within ±2**53 (9007199254740992), for example by subtracting an offset",
        ),
        (
            "u64",
            float(UINT64_MAX),
            "holds 1.8446744073709552e+19 at t=0 s for the FMU's UInt64 input 'u64', which is "
            "beyond 2**53, the largest whole number float64 (the type channels are read as) "
            "holds exactly: the file's value may have been rounded; keep the channel's values "
            "within ±2**53 (9007199254740992), for example by subtracting an offset",
        ),
        (
            "u64",
            -1.0,
            "holds -1 at t=0 s for the FMU's UInt64 input 'u64', outside its range "
            "0..18446744073709551615; feed the input a channel within that range",
        ),
        (
            "i64",
            2.5,
            "holds 2.5 at t=0 s for the FMU's Int64 input 'i64', which is no whole number; "
            "feed the input a channel of whole numbers",
        ),
    ],
)
def test_integer_inputs_it_cannot_pass_exactly_are_refused(
    probe: str, variable: str, value: float, expected: str
) -> None:
    reference = _reference(c=(TIME, np.full(TIME.size, value)))
    assert _error(probe, reference, inputs={variable: "c"}) == (
        f"measured.csv: column 'c': {expected}"
    )


def test_int64_max_in_a_csv_file_is_refused_not_wrapped(probe: str, tmp_path: Path) -> None:
    path = tmp_path / "ints.csv"
    path.write_text(f"time,big\n0,{INT64_MAX}\n1,{INT64_MAX}\n")
    reference = read_record(str(path), ["big"], SourceOptions())
    message = _error(probe, reference, inputs={"i64": "big"})
    assert message.startswith(f"{path}: column 'big': holds 9.2233720368547758e+18 at t=0 s")


@pytest.mark.parametrize(
    ("variable", "kind"),
    [("gains", "an array of 2 Float64 values"), ("mode", "a String variable")],
)
def test_inputs_one_channel_cannot_drive_are_refused(probe: str, variable: str, kind: str) -> None:
    assert _error(probe, inputs={variable: "zero"}) == (
        f"probe3.fmu: inputs: input {variable!r} is {kind}, which one measured channel cannot "
        f"drive; remove {variable!r} from the inputs; the FMU then uses its start value"
    )


def test_parameters_keep_their_declared_type(probe: str) -> None:
    record = _run(
        probe,
        outputs={"length": "label_length", "y": "y[1]", "offsets": "offset_sum"},
        # YAML 1.1 reads 2e0 as text: the declared type (Float64) makes it a number.
        parameters={"label": "twelve chars", "k": "2e0", "offsets": [1.5, 2]},
    )
    np.testing.assert_array_equal(record.channels["length"].values, 12.0)
    np.testing.assert_array_equal(record.channels["offsets"].values, 1.5 + 10 * 2)
    np.testing.assert_allclose(record.channels["y"].values, np.exp(-2 * TIME), rtol=1e-12)


@pytest.mark.parametrize(
    ("parameters", "expected"),
    [
        (
            {"label": 3},
            "parameter 'label' is a String variable; 3 is not text; give 'label' text (in "
            "YAML, quote a value that reads as a number: '3')",
        ),
        (
            {"k": "fast"},
            "parameter 'k' is a Float64 variable; 'fast' is not a number; give 'k' a number",
        ),
        (
            {"k": True},
            "parameter 'k' is a Float64 variable; True is not a number; give 'k' a number",
        ),
        (
            {"offsets": [1.0]},
            "parameter 'offsets' is an array of 2 Float64 values; [1.0] is not a list of 2 "
            "values; give 'offsets' a list of 2 values",
        ),
        (
            {"offsets": [1.0, "x"]},
            "parameter 'offsets' is an array of 2 Float64 values; 'x' is not a number; give "
            "'offsets' a number",
        ),
        (
            {"blob": "x"},
            "parameter 'blob' is a Binary variable, which a spec cannot set; remove 'blob' from "
            "the parameters",
        ),
    ],
)
def test_parameters_of_the_wrong_type_are_explained(
    probe: str, parameters: dict[str, object], expected: str
) -> None:
    assert _error(probe, parameters=parameters) == f"probe3.fmu: parameters: {expected}"


@pytest.mark.parametrize(
    ("output", "kind", "holds"), [("label_out", "String", "text"), ("blob", "Binary", "bytes")]
)
def test_text_and_binary_outputs_cannot_be_scored(
    probe: str, output: str, kind: str, holds: str
) -> None:
    assert _error(probe, outputs={"name": output}) == (
        f"probe3.fmu: outputs: output {output!r} is a {kind} variable: it holds {holds}, not "
        "numbers, and cannot be scored; remove 'name' from the outputs; the FMU's numeric "
        "outputs: 'i64_out', 'u64_out', 'y', 'm', 'label_length', 'tol_seen', 'start_seen', "
        "'u_out', 'offset_sum'"
    )


def test_start_time_and_tolerance_reach_a_co_simulation(probe: str) -> None:
    record = _run(
        probe, outputs={"tol": "tol_seen", "start": "start_seen"}, start_time=0.3, tolerance=1e-7
    )
    assert record.meta["fmi_type"] == "CoSimulation"
    np.testing.assert_array_equal(record.channels["tol"].values, 1e-7)
    np.testing.assert_array_equal(record.channels["start"].values, 0.3)
    np.testing.assert_allclose(record.channels["tol"].time[[0, -1]], [0.3, 1.0])


def test_model_exchange_is_chosen_and_solved_to_the_tolerance(probe: str) -> None:
    def error(tolerance: float) -> float:
        record = _run(
            probe,
            interface="model-exchange",
            tolerance=tolerance,
            start_time=0.2,
            outputs={"x": "y[1]"},
        )
        assert record.meta["fmi_type"] == "ModelExchange"
        x = record.channels["x"]
        return float(np.max(np.abs(x.values - np.exp(-(x.time - 0.2)))))

    loose, tight = error(1e-1), error(1e-9)
    assert tight < 1e-6
    assert loose > 100 * tight


EVENT_ROWS = "time,u\n0,0\n0.2,0\n0.5,0\n0.5,1\n0.8,1\n1.0,1\n"


def test_events_in_an_input_file_reach_fmpy_as_events(
    probe: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "events.csv"
    path.write_text(EVENT_ROWS)
    reference = read_record(str(path), ["u"], SourceOptions(extra={"events": True}))
    u = reference.channels["u"]
    # Scoring sees a step: the value before the event up to its instant, the value after it
    # from there on; time still increases strictly.
    assert u.time[2] == np.nextafter(0.5, 0)
    assert u.time[3] == 0.5
    np.testing.assert_array_equal(u.values, [0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(reference.meta["events"], [0.5])

    seen: dict[str, Any] = {}
    simulate = fmpy.simulate_fmu

    def spy(*args: Any, **kwargs: Any) -> Any:
        seen["input"] = kwargs["input"].copy()
        return simulate(*args, **kwargs)

    monkeypatch.setattr(fmpy, "simulate_fmu", spy)
    record = _run(
        probe,
        reference,
        interface="model-exchange",
        inputs={"u": "u"},
        outputs={"u": "u_out"},
        step_size=0.1,
    )
    np.testing.assert_array_equal(seen["input"]["time"], [0, 0.2, 0.5, 0.5, 0.8, 1.0])
    np.testing.assert_array_equal(seen["input"]["u"], [0, 0, 0, 1, 1, 1])
    out = record.channels["u"]
    np.testing.assert_allclose(out.values, np.where(out.time < 0.5 - 1e-9, 0.0, 1.0), atol=1e-12)


def test_three_rows_at_one_time_stamp_are_no_event(tmp_path: Path) -> None:
    path = tmp_path / "events.csv"
    path.write_text("time,u\n0,0\n0.5,0\n0.5,1\n0.5,2\n1,2\n")
    with pytest.raises(DataError) as info:
        read_record(str(path), ["u"], SourceOptions(extra={"events": True}))
    assert str(info.value) == (
        f"{path}:5: column 'time': three rows at t=0.5 (index 1 to 3); an event has two, the "
        "values before and after it; keep two rows per time stamp at most"
    )


def _spec(root: Path, model: str, reference: str = "measured.csv") -> Path:
    path = root / "m.hevval.yaml"
    path.write_text(f"name: m\nreference: {reference}\nmodel: {model}\nsets:\n  - {{signal: u}}\n")
    return path


@pytest.mark.parametrize(
    ("model", "expected"),
    [
        (
            "{fmu: p.fmu, interface: modelexchange}",
            ":3: model.interface: must be one of co-simulation, model-exchange (got "
            "'modelexchange'); did you mean 'model-exchange'?",
        ),
        (
            "{fmu: p.fmu, tolerance: 1}",
            ":3: model.tolerance: must be a relative tolerance, greater than 0 and less than 1 "
            "(such as 1e-6) (got 1.0)",
        ),
        (
            "{fmu: p.fmu, tolerance: 0}",
            ":3: model.tolerance: must be a relative tolerance, greater than 0 and less than 1 "
            "(such as 1e-6) (got 0.0)",
        ),
        (
            "{fmu: p.fmu, start_time: 5, stop_time: 2}",
            ":3: model.stop_time: must be later than start_time (5) (got 2.0)",
        ),
        ("{fmu: p.fmu, start_time: soon}", ":3: model.start_time: must be a number (got 'soon')"),
        (
            "{path: sim.csv, interface: co-simulation}",
            ":3: model.interface: applies to an FMU model, not a file; remove `interface:`",
        ),
        (
            "{callable: 'm:f', tolerance: 1.0e-6}",
            ":3: model.tolerance: applies to an FMU model, not a callable; remove `tolerance:`",
        ),
    ],
)
def test_fmu_keys_are_checked(tmp_path: Path, model: str, expected: str) -> None:
    path = _spec(tmp_path, model)
    with pytest.raises(SpecError) as info:
        load_spec(path)
    assert str(info.value) == f"{path}{expected}"


def test_fmu_keys_are_read(tmp_path: Path) -> None:
    spec = load_spec(
        _spec(
            tmp_path,
            "{fmu: p.fmu, interface: model-exchange, start_time: 1, stop_time: 9, "
            "tolerance: 1.0e-6}",
        )
    )
    run = spec.model.fmu_run
    assert (run.interface, run.start_time, run.stop_time, run.tolerance) == (
        "model-exchange",
        1.0,
        9.0,
        1e-6,
    )
    # The reference of an FMU model may hold events; a file model's may not.
    assert spec.reference.options.extra["events"] is True
    assert "events" not in load_spec(_spec(tmp_path, "sim.csv")).reference.options.extra


def _project(pytester: pytest.Pytester, probe: str) -> Path:
    root = pytester.path
    (root / "probe3.fmu").write_bytes(Path(probe).read_bytes())
    t = np.round(np.arange(0, 4.0001, 0.01), 10)
    x = np.exp(-0.5 * (t - 1.0))
    lines = ["time,x,y[2],count,u"]
    for ti, xi in zip(t, x, strict=True):
        lines.append(f"{ti:.2f},{xi:.17g},{2 * xi:.17g},{int(ti * 10)},{float(ti >= 2):g}")
    (root / "measured.csv").write_text("\n".join(lines) + "\n")
    return root


PROBE_SPEC = """\
name: probe
reference: measured.csv
model:
  fmu: probe3.fmu
  interface: model-exchange
  start_time: 1.0
  tolerance: 1.0e-9
  step_size: 0.01
  params: {{k: 0.5, label: "{label}"}}
  inputs: {{i64: count}}
  outputs: {{first: "y[1]", y: y, n: label_length}}
thresholds: {{mae: 0.999}}
sets:
  - {{signal: decay, ref: x, sim: first}}
  - {{signal: second, ref: "y[2]", sim: "y[2]"}}
  - {{signal: label, ref: x, sim: "first * n / 5"}}
"""


def test_a_spec_scores_array_elements_of_a_model_exchange_run(
    pytester: pytest.Pytester, probe: str
) -> None:
    _project(pytester, probe)
    pytester.makefile(".hevval.yaml", probe=PROBE_SPEC.format(label="hello"))
    result = pytester.runpytest("--hevval", "-v", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=4)
    result.stdout.fnmatch_lines(["*probe.hevval.yaml::decay PASSED*", "probe: Φ = 1.0000*"])

    # The String parameter arrived: a label of another length fails that signal alone.
    pytester.makefile(".hevval.yaml", probe=PROBE_SPEC.format(label="hello!"))
    result = pytester.runpytest("--hevval", "-v", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=3, failed=1)
    result.stdout.fnmatch_lines(["*probe.hevval.yaml::label FAILED*"])


def test_a_spec_feeds_an_input_file_with_events(pytester: pytest.Pytester, probe: str) -> None:
    _project(pytester, probe)
    pytester.makefile(
        ".hevval.yaml",
        events="""\
name: events
reference: events.csv
model:
  fmu: probe3.fmu
  interface: model-exchange
  step_size: 0.1
  inputs: {u: u}
  outputs: {u: u_out}
thresholds: {mae: 0.999}
sets:
  - {signal: u}
""",
    )
    rows = ["time,u"] + [f"{t / 10:g},0" for t in range(6)] + ["0.5,1"]
    rows += [f"{t / 10:g},1" for t in range(6, 21)]
    (pytester.path / "events.csv").write_text("\n".join(rows) + "\n")
    result = pytester.runpytest("--hevval", "-v", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(["events: Φ = 1.0000*"])


def test_without_outputs_every_numeric_output_is_recorded(probe: str) -> None:
    record = _run(probe, outputs={})
    assert list(record.channels) == [
        "i64_out",
        "u64_out",
        *ELEMENTS,
        "label_length",
        "tol_seen",
        "start_seen",
        "u_out",
        "offset_sum",
    ]
    assert record.meta["unscored"] == {
        "label_out": "output 'label_out' is a String variable: it holds text, not numbers, "
        "and cannot be scored",
        "blob": "output 'blob' is a Binary variable: it holds bytes, not numbers, and cannot "
        "be scored",
    }
    with pytest.raises(DataError) as info:
        record.channel("label_out")
    assert str(info.value) == (
        f"{probe}: column 'label_out': output 'label_out' is a String variable: it holds "
        "text, not numbers, and cannot be scored; score a numeric column"
    )


def test_a_spec_without_outputs_notes_the_text_outputs_it_left_out(
    pytester: pytest.Pytester, probe: str
) -> None:
    _project(pytester, probe)
    spec = """\
name: free
reference: measured.csv
model: {{fmu: probe3.fmu, params: {{k: 0.5}}, start_time: 1.0, step_size: 0.01}}
sets:
  - {{signal: decay, ref: x, sim: "{sim}"}}
"""
    pytester.makefile(".hevval.yaml", free=spec.format(sim="y[1]"))
    result = pytester.run(
        sys.executable, "-m", "pytest_hevval", "run", "free.hevval.yaml", "--json", "out.json"
    )
    assert result.ret == 0, result.stderr.str()
    payload = json.loads((pytester.path / "out.json").read_text())
    assert payload["data"]["model"]["unscored_outputs"] == {
        "label_out": "output 'label_out' is a String variable: it holds text, not numbers, "
        "and cannot be scored",
        "blob": "output 'blob' is a Binary variable: it holds bytes, not numbers, and cannot "
        "be scored",
    }

    pytester.makefile(".hevval.yaml", free=spec.format(sim="label_out"))
    result = pytester.runpytest("--hevval", "-p", "no:cacheprovider")
    assert result.ret != 0
    result.stdout.fnmatch_lines(
        [
            "*probe3.fmu: column 'label_out': output 'label_out' is a String variable: it "
            "holds text, not numbers, and cannot be scored; score a numeric column*"
        ]
    )
    assert "Traceback" not in result.stdout.str()


@pytest.mark.parametrize("interface", ["co-simulation", "model-exchange"])
def test_an_fmi2_fmu_runs_either_interface_with_its_settings(probe2: str, interface: str) -> None:
    slow = np.round(np.arange(0, 1.0001, 0.1), 10)
    counts = np.arange(slow.size) * 7.0 - 20.0
    reference = _reference(count=(slow, counts))
    record = _run(
        probe2,
        reference,
        interface=interface,
        inputs={"n": "count"},
        outputs={"y": "y", "n": "n_out", "tol": "tol_seen", "start": "start_seen"},
        parameters={"k": 0.5},
        start_time=0.2,
        tolerance=1e-9,
    )
    assert record.meta["fmi_version"] == "2.0"
    y = record.channels["y"]
    np.testing.assert_allclose(y.values, np.exp(-0.5 * (y.time - 0.2)), rtol=1e-6)
    np.testing.assert_array_equal(record.channels["start"].values, 0.2)
    n = record.channels["n"]
    held = np.searchsorted(slow, n.time + 1e-9, side="right") - 1
    if interface == "co-simulation":
        # fmi2SetupExperiment gets the tolerance; a step reads the input at its start.
        assert record.meta["fmi_type"] == "CoSimulation"
        np.testing.assert_array_equal(record.channels["tol"].values, 1e-9)
        np.testing.assert_array_equal(n.values[1:], counts[held[:-1]])
    else:
        # CVode solves to the tolerance; the model reads the input at each output time.
        assert record.meta["fmi_type"] == "ModelExchange"
        np.testing.assert_array_equal(n.values, counts[held])

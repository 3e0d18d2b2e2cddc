"""Spec files: what loads, and the exact message for each kind of mistake."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from pytest_hevval.errors import SpecError
from pytest_hevval.spec.load import load_spec, parse_spec_text

GOOD = """\
name: bus
reference: {path: data/ref.csv, time: "Time [s]"}
model: {path: data/sim.csv, time: time}
alignment: {rate_hz: 10, window: [0, 100], max_lag_s: 5}
thresholds: {lambda3: 0.9, rms: 0.8}
weights: {mae: 2}
min_phi: 0.9
sets:
  - signal: FCcum
    ref: integrate(FC)
    sim: integrate(FC)
    thresholds: {mae: 0.95}
    children:
      - signal: FCinst
        ref: FC
        alpha: 0.7
        children:
          - {signal: Neng, alpha: 0.5}
          - {signal: Teng, ref: "`Engine Torque [Nm]`", alpha: 0.5, interpolation: previous}
  - {signal: v, ref: "Velocity [km/h]"}
"""


def parse(text: str, name: str = "trip.hevval.yaml") -> object:
    return parse_spec_text(textwrap.dedent(text), Path("/project") / name)


def test_good_spec_loads_with_lines_and_defaults() -> None:
    spec = parse_spec_text(GOOD, Path("/project/bus.hevval.yaml"))
    assert spec.name == "bus"
    assert spec.reference.path == "/project/data/ref.csv"
    assert spec.reference.options.time == "Time [s]"
    assert spec.alignment.window == (0.0, 100.0)
    assert spec.thresholds == {"mae": 0.9, "rms": 0.8}
    assert spec.weights == {"mae": 2.0}
    assert spec.beta() == {
        "lag_correlation": 1.0,
        "derivative_match": 1.0,
        "mae": 2.0,
        "rms": 1.0,
        "anomaly": 1.0,
        "error_std": 1.0,
        "emergent": 1.0,
    }
    walked = [("/".join(path), node.line, index) for index, path, node in spec.walk()]
    assert walked == [
        ("FCcum", 9, 1),
        ("FCcum/FCinst", 14, 1),
        ("FCcum/FCinst/Neng", 18, 1),
        ("FCcum/FCinst/Teng", 19, 1),
        ("v", 20, 2),
    ]
    teng = spec.sets[0].children[0].children[1]
    assert teng.ref.columns == ("Engine Torque [Nm]",)
    assert teng.sim.source == "Teng"
    assert teng.interpolation == "previous"
    assert spec.sets[1].ref.is_column
    assert spec.reference_columns() == {"FC", "Neng", "Engine Torque [Nm]", "Velocity [km/h]"}
    fccum = spec.sets[0]
    assert spec.thresholds_for(("FCcum",), fccum) == {"mae": 0.95, "rms": 0.8}


def test_name_defaults_to_file_name() -> None:
    text = GOOD.replace("name: bus\n", "")
    assert parse_spec_text(text, Path("/p/trip_a01.hevval.yaml")).name == "trip_a01"


def test_load_spec_reads_a_file(tmp_path: Path) -> None:
    path = tmp_path / "x.hevval.yaml"
    path.write_text(GOOD)
    spec = load_spec(path)
    assert spec.reference.path == str(tmp_path / "data" / "ref.csv")
    assert len(spec.text_hash) == 64


MINIMAL = """\
reference: ref.csv
model: {path: sim.csv}
sets:
  - signal: v
"""

# (spec text, exact message). Each names file:line, the key path and what to do.
MALFORMED = [
    ("", "/p/t.hevval.yaml:1: the spec file is empty; see docs/spec.md for the format"),
    (
        "reference: [unclosed\n",
        "/p/t.hevval.yaml:2: invalid YAML: expected ',' or ']', but got '<stream end>'",
    ),
    ("- a\n- b\n", "/p/t.hevval.yaml:1: must be a mapping of keys to values (got a list)"),
    (
        MINIMAL + "min_phy: 0.9\n",
        "/p/t.hevval.yaml:5: min_phy: unknown key; did you mean 'min_phi'?",
    ),
    (
        MINIMAL.replace("reference: ref.csv\n", ""),
        "/p/t.hevval.yaml:1: reference: is required; see docs/spec.md for the format",
    ),
    (
        MINIMAL + "min_phi: 1.5\n",
        "/p/t.hevval.yaml:5: min_phi: must lie between 0 and 1 (got 1.5)",
    ),
    (
        MINIMAL + "min_phi: high\n",
        "/p/t.hevval.yaml:5: min_phi: must be a number (got 'high')",
    ),
    (
        MINIMAL + "thresholds: {maee: 0.9}\n",
        "/p/t.hevval.yaml:5: thresholds.maee: unknown characteristic; did you mean 'mae'?",
    ),
    (
        MINIMAL + "thresholds: {mae: 0.9, lambda3: 0.8}\n",
        "/p/t.hevval.yaml:5: thresholds.lambda3: repeats mae",
    ),
    (
        MINIMAL + "thresholds: {rms: -0.1}\n",
        "/p/t.hevval.yaml:5: thresholds.rms: must lie between 0 and 1 (got -0.1)",
    ),
    (
        MINIMAL + "weights: {mae: -1}\n",
        "/p/t.hevval.yaml:5: weights.mae: must be 0 or more (got -1)",
    ),
    (
        MINIMAL + "alignment: {window: [10, 5]}\n",
        "/p/t.hevval.yaml:5: alignment.window: stop must be later than start (got [10.0, 5.0])",
    ),
    (
        MINIMAL + "alignment: {rate: 10}\n",
        "/p/t.hevval.yaml:5: alignment.rate: unknown key; did you mean 'rate_hz'?",
    ),
    (
        MINIMAL + "alignment: {nan: drop}\n",
        "/p/t.hevval.yaml:5: alignment.nan: must be one of raise, omit (got 'drop')",
    ),
    (
        MINIMAL + "correlation: spearman\n",
        "/p/t.hevval.yaml:5: correlation: must be one of xcorr, pearson (got 'spearman'); "
        "did you mean 'pearson'?",
    ),
    (
        MINIMAL.replace("model: {path: sim.csv}", "model: {path: a.csv, callable: 'm:f'}"),
        "/p/t.hevval.yaml:2: model: needs exactly one of path, callable or fmu "
        "(got ['path', 'callable'])",
    ),
    (
        MINIMAL.replace("model: {path: sim.csv}", "model: {callable: 'models.ev'}"),
        "/p/t.hevval.yaml:2: model.callable: must look like 'package.module:function' "
        "(got 'models.ev')",
    ),
    (
        MINIMAL.replace("sets:\n  - signal: v\n", "sets: []\n"),
        "/p/t.hevval.yaml:3: sets: must be a non-empty list of signals (got a list)",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {signl: v}\n"),
        "/p/t.hevval.yaml:4: sets[0].signl: unknown key; did you mean 'signal'?",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {ref: v}\n"),
        "/p/t.hevval.yaml:4: sets[0].signal: is required (the signal's name)",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {signal: v, alpha: -2}\n"),
        "/p/t.hevval.yaml:4: sets[0].alpha: must be 0 or more (got -2)",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {signal: a/b}\n"),
        "/p/t.hevval.yaml:4: sets[0].signal: must be a non-empty name on one line, of printable "
        "characters, without '/' or '::' "
        "(got 'a/b')",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {signal: v, interpolation: cubic}\n"),
        "/p/t.hevval.yaml:4: sets[0].interpolation: must be one of linear, previous (got 'cubic')",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {signal: v, children: {signal: w}}\n"),
        "/p/t.hevval.yaml:4: sets[0].children: must be a list of signals (got a mapping)",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - signal: v\n  - signal: v\n"),
        "/p/t.hevval.yaml:5: sets[1]: duplicate signal path 'v' (first defined at line 4); "
        "give it another name",
    ),
    (
        MINIMAL.replace(
            "  - signal: v\n",
            "  - signal: E\n    children:\n      - {signal: P, thresholds: {rms: 2}}\n",
        ),
        "/p/t.hevval.yaml:6: sets[0].children[0].thresholds.rms: must lie between 0 and 1 (got 2)",
    ),
    (
        MINIMAL.replace("  - signal: v\n", "  - {signal: v, ref: '__import__(`os`)'}\n"),
        "/p/t.hevval.yaml:4: sets[0].ref:",
    ),
    (
        MINIMAL + "reference: again.csv\n",
        "/p/t.hevval.yaml:5: invalid YAML: found duplicate key 'reference'",
    ),
]


@pytest.mark.parametrize(("text", "message"), MALFORMED)
def test_malformed_spec_messages(text: str, message: str) -> None:
    with pytest.raises(SpecError) as info:
        parse_spec_text(text, Path("/p/t.hevval.yaml"))
    if message.endswith(":"):
        assert str(info.value).startswith(message)
    else:
        assert str(info.value) == message


def test_expression_error_carries_the_spec_location() -> None:
    text = MINIMAL.replace("  - signal: v\n", "  - {signal: v, ref: 'v.__class__'}\n")
    with pytest.raises(SpecError) as info:
        parse_spec_text(text, Path("/p/t.hevval.yaml"))
    error = info.value
    assert (error.file, error.line, error.key) == ("/p/t.hevval.yaml", 4, "sets[0].ref")
    assert "not allowed" in str(error)


def test_unreadable_spec_file(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match=r"missing\.hevval\.yaml: cannot read the spec file"):
        load_spec(tmp_path / "missing.hevval.yaml")


def test_non_utf8_spec_file(tmp_path: Path) -> None:
    path = tmp_path / "latin.hevval.yaml"
    path.write_bytes(b"name: caf\xe9\n")
    with pytest.raises(SpecError, match="not UTF-8 text"):
        load_spec(path)


def test_spec_errors_survive_pickling() -> None:
    import pickle

    error = SpecError("bad", file="f.yaml", line=3, key="sets[0]", hint="fix it")
    copy = pickle.loads(pickle.dumps(error))
    assert str(copy) == str(error) == "f.yaml:3: sets[0]: bad; fix it"
    assert copy.line == 3


def test_all_alphas_zero_is_a_spec_error_not_a_traceback() -> None:
    text = (
        "reference: ref.csv\nmodel: {path: sim.csv}\n"
        "sets:\n  - {signal: v, alpha: 0}\n  - {signal: w, alpha: 0}\n"
    )
    with pytest.raises(SpecError) as info:
        parse_spec_text(text, Path("/p/t.hevval.yaml"))
    assert str(info.value) == (
        "/p/t.hevval.yaml:3: sets: every signal's alpha is zero, so Φ is undefined; "
        "give at least one signal an alpha above 0"
    )

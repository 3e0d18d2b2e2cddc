"""The characteristic registry: user characteristics end to end, errors, keyed Φ, old records."""

from __future__ import annotations

import json
import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval import (
    Characteristic,
    CharacteristicError,
    CharacteristicValue,
    global_metric,
    register_characteristic,
)
from pytest_hevval.core.registry import (
    PAPER_CHARACTERISTICS,
    compute_characteristic,
    registry_snapshot,
    restore_registry,
)
from pytest_hevval.history import migrate_record
from pytest_hevval.results.spec_result import SpecResult
from tests.test_plugin import write_data

pytest_plugins = ["pytester"]


@pytest.fixture(autouse=True)
def _registry_isolation() -> Iterator[None]:
    """Characteristics registered by a test (or an in-process conftest) end with it."""
    saved = registry_snapshot()
    yield
    restore_registry(saved)


DATA = Path(__file__).parent / "data" / "history"

CONFTEST = """
from pytest_hevval import Characteristic, CharacteristicValue, register_characteristic


def peak_error(ref, sim, dt):
    span = ref.max() - ref.min()
    gap = abs(ref.max() - sim.max())
    return CharacteristicValue(1.0 - gap / span, {"peak_gap": float(gap)})


register_characteristic(
    Characteristic(name="peak_error", label="peak error", compute=peak_error)
)
"""

SPEC = """\
name: pack
reference: {path: data/ref.csv, time: t}
model: {path: data/sim.csv, time: time}
alignment: {max_lag_s: 2}
thresholds: {mae: 0.5}
weights: {peak_error: 2}
sets:
  - signal: P
    ref: V * I
    unit: W
    children:
      - {signal: V, unit: V}
      - {signal: I, unit: A, thresholds: {peak_error: PEAK}}
"""


@pytest.mark.parametrize("xdist", [False, True], ids=["serial", "xdist"])
def test_conftest_characteristic_end_to_end(pytester: pytest.Pytester, xdist: bool) -> None:
    pytester.makeconftest(CONFTEST)
    pytester.makefile(".hevval.yaml", pack=SPEC.replace("PEAK", "0.5"))
    write_data(pytester.path, fault="leaf")
    extra = ["-p", "xdist", "-n", "2"] if xdist else []
    loose = pytester.runpytest("--hevval", "--hevval-history", "--hevval-model-version=a", *extra)
    loose.assert_outcomes(passed=4)

    pytester.makefile(".hevval.yaml", pack=SPEC.replace("PEAK", "0.99"))
    gated = pytester.runpytest(
        "--hevval",
        "--hevval-history",
        "--hevval-model-version=b",
        "--hevval-report=html,json,md",
        "--junitxml=junit.xml",
        "--hevval-compare",
        *extra,
    )
    gated.assert_outcomes(passed=3, failed=1)
    gated.stdout.fnmatch_lines(["*peak error = 0.* < 0.99 (peak_gap *)*"])
    gated.stdout.fnmatch_lines(["*peak_error*"])  # the comparison with run a

    report = pytester.path / ".hevval" / "report"
    document = json.loads((report / "report.json").read_text())
    spec = (document["specs"] if isinstance(document, dict) else document)[0]
    assert spec["schema_version"] == 2
    assert spec["weights"]["peak_error"] == 2.0
    current = next(s for s in spec["signals"] if s["path"] == "P/I")
    assert set(current["lambdas"]) == {*PAPER_CHARACTERISTICS, "peak_error"}
    assert current["lambdas"]["peak_error"] < 0.99
    assert current["components"]["peak_error"]["peak_gap"] > 0
    assert [f["characteristic"] for f in current["failures"]] == ["peak_error"]
    assert "peak_error" in (report / "report.html").read_text()
    assert "peak error" in (report / "report.md").read_text()
    junit = ET.parse(pytester.path / "junit.xml")
    properties = {
        (p.get("name"), p.get("value"))
        for case in junit.iter("testcase")
        if case.get("name") == "P/I"
        for p in case.iter("property")
    }
    assert ("peak_error", f"{current['lambdas']['peak_error']:.6f}") in properties
    assert ("lambda3_mae", f"{current['lambdas']['mae']:.6f}") in properties

    # Φ weighs the new characteristic with β = 2 (eq. 14 by hand).
    numerator = denominator = 0.0
    for signal in spec["signals"]:
        for name, value in signal["lambdas"].items():
            beta = 2.0 if name == "peak_error" else 1.0
            numerator += signal["alpha"] * beta * value
            denominator += signal["alpha"] * beta
    assert spec["phi"] == pytest.approx(numerator / denominator, rel=1e-12)

    records = sorted((pytester.path / ".hevval" / "history").glob("*.json"))
    stored = json.loads(records[-1].read_text())
    assert stored["schema_version"] == 4
    signal = next(s for s in stored["specs"][0]["signals"] if s["path"] == "P/I")
    assert signal["lambdas"]["peak_error"] == current["lambdas"]["peak_error"]

    # The CLI reads no conftest: the names stored in the records are enough.
    history = ["--history-dir", ".hevval/history"]
    compared = pytester.run(
        sys.executable,
        "-m",
        "pytest_hevval",
        "compare",
        "history:a",
        "history:b",
        *history,
        "--format",
        "json",
        "--compare-fail",
        "lambda:0.001",
    )
    assert compared.ret == 0, compared.stderr.str()
    document = json.loads(compared.stdout.str())
    assert document["regressions"] == []
    deltas = document["comparison"]["specs"][0]["signals"]
    by_path = {s["path"]: s for s in deltas}
    assert by_path["P/I"]["lambdas"]["peak_error"]["after"] == current["lambdas"]["peak_error"]
    table = pytester.run(
        sys.executable, "-m", "pytest_hevval", "history", "--signal", "P/I", *history
    )
    assert table.ret == 0, table.stderr.str()
    table.stdout.fnmatch_lines(["*λ1*λ7*peak_error*lag s*"])


def test_unknown_metric_gets_did_you_mean(pytester: pytest.Pytester) -> None:
    pytester.makefile(
        ".hevval.yaml",
        pack=SPEC.replace("PEAK", "0.5").replace("weights:", "metrics: [mea]\nweights:"),
    )
    write_data(pytester.path)
    result = pytester.runpytest("--hevval")
    result.stdout.fnmatch_lines(["*metrics[[]0]: unknown characteristic 'mea'*did you mean 'mae'*"])


def test_builtin_name_clashes() -> None:
    with pytest.raises(CharacteristicError, match="'mae' is a built-in characteristic"):
        register_characteristic(Characteristic(name="mae", label="mine", compute=lambda r, s, d: 1))


def test_registration_is_idempotent_but_redefinition_clashes() -> None:
    def score(ref: object, sim: object, dt: float) -> float:
        return 1.0

    first = Characteristic(name="idempotent_probe", label="probe", compute=score)
    assert register_characteristic(first) is register_characteristic(first)
    again = Characteristic(name="idempotent_probe", label="probe", compute=score)
    assert register_characteristic(again).name == "idempotent_probe"
    with pytest.raises(CharacteristicError, match="'idempotent_probe' is already registered"):
        register_characteristic(
            Characteristic(name="idempotent_probe", label="other", compute=score)
        )


@pytest.mark.parametrize("bad", [1.5, -0.1, math.nan, "high"])
def test_compute_outside_unit_interval_is_refused(bad: object) -> None:
    characteristic = Characteristic(name="bad_probe", label="bad", compute=lambda r, s, d: bad)
    ref = np.arange(4.0)
    with pytest.raises(CharacteristicError, match="'bad_probe' returned"):
        compute_characteristic(characteristic, ref, ref, 0.1)


def test_compute_with_components() -> None:
    characteristic = Characteristic(
        name="parts_probe",
        label="parts",
        compute=lambda r, s, d: CharacteristicValue(0.25, {"a": 1.0}),
    )
    value = compute_characteristic(characteristic, np.zeros(3), np.zeros(3), 1.0)
    assert value == CharacteristicValue(0.25, {"a": 1.0})


@pytest.mark.parametrize("stored", ["schema1_camry_hwfet.json", "schema2_camry_hwfet.json"])
def test_stored_old_records_migrate_to_keyed_lambdas(stored: str) -> None:
    schema2 = json.loads((DATA / "schema2_camry_hwfet.json").read_text())
    migrated = migrate_record(json.loads((DATA / stored).read_text()), file=stored)
    assert migrated["schema_version"] == 4
    assert (migrated["accepted"], migrated["acceptance"]) == (True, "earlier-schema")
    assert migrated["model_version"] == "v1.0"
    assert migrated["started_utc"] == schema2["started_utc"]
    for old_spec, new_spec in zip(schema2["specs"], migrated["specs"], strict=True):
        assert new_spec["weights"] == dict.fromkeys(PAPER_CHARACTERISTICS, 1.0)
        assert new_spec["phi"] == old_spec["phi"]
        for old, new in zip(old_spec["signals"], new_spec["signals"], strict=True):
            assert new["lambdas"] == dict(zip(PAPER_CHARACTERISTICS, old["lambdas"], strict=True))
        result = SpecResult.from_dict(new_spec)
        assert result.signals[0].lambdas["emergent"] == old_spec["signals"][0]["lambdas"][6]
        assert result.signals[0].mae == old_spec["signals"][0]["mae"]


unit = st.floats(0.0, 1.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    rows=st.lists(
        # Subnormal α times β underflows to 0: eq. 14 is then 0/0, a spec error at load time.
        st.tuples(
            st.floats(0.0, 5.0, allow_nan=False, allow_subnormal=False),
            st.lists(unit, min_size=7, max_size=7),
        ),
        min_size=1,
        max_size=6,
    ),
    beta=st.lists(st.floats(0.01, 3.0, allow_nan=False), min_size=7, max_size=7),
)
def test_keyed_phi_is_equation_14(rows: list[tuple[float, list[float]]], beta: list[float]) -> None:
    if sum(alpha for alpha, _ in rows) == 0:
        return
    keyed_rows = [
        (alpha, dict(zip(PAPER_CHARACTERISTICS, lam, strict=True))) for alpha, lam in rows
    ]
    keyed_beta = dict(zip(PAPER_CHARACTERISTICS, beta, strict=True))
    numerator = sum(a * b * v for a, lam in rows for b, v in zip(beta, lam, strict=True))
    denominator = sum(a * b for a, _ in rows for b in beta)
    assert global_metric(keyed_rows, keyed_beta) == pytest.approx(
        numerator / denominator, rel=1e-12
    )


def _nan_score(ref: object, sim: object, dt: float) -> float:
    return math.nan


OFF_BY_DEFAULT = Characteristic(
    name="nan_probe", label="nan probe", compute=_nan_score, enabled_by_default=False
)


def test_disabled_characteristic_is_scored_only_when_named_in_metrics(tmp_path: Path) -> None:
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import parse_spec_text

    register_characteristic(OFF_BY_DEFAULT)
    write_data(tmp_path)
    text = SPEC.replace("PEAK", "0.5").replace("weights: {peak_error: 2}\n", "")
    text = text.replace("thresholds: {peak_error: 0.5}", "thresholds: {mae: 0.1}")
    plain = evaluate_spec(parse_spec_text(text, tmp_path / "pack.hevval.yaml")).result
    assert "nan_probe" not in plain.signals[0].lambdas
    assert "nan_probe" not in plain.weights

    with pytest.raises(CharacteristicError) as info:
        evaluate_spec(
            parse_spec_text("metrics: [nan_probe]\n" + text, tmp_path / "pack.hevval.yaml")
        )
    message = str(info.value)
    assert "pack.hevval.yaml" in message
    assert "'nan_probe' returned nan, outside [0, 1] for signal 'P'" in message


def test_threshold_on_an_unscored_characteristic_is_a_spec_error(tmp_path: Path) -> None:
    from pytest_hevval.errors import SpecError
    from pytest_hevval.spec.load import parse_spec_text

    register_characteristic(OFF_BY_DEFAULT)
    text = SPEC.replace("PEAK", "0.5").replace("weights: {peak_error: 2}\n", "")
    text = text.replace("thresholds: {peak_error: 0.5}", "thresholds: {nan_probe: 0.5}")
    with pytest.raises(SpecError, match="'nan_probe' is not scored by this spec") as info:
        parse_spec_text(text, tmp_path / "pack.hevval.yaml")
    assert "metrics: [nan_probe]" in str(info.value)


def test_entry_points_register_once(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.metadata

    from pytest_hevval.core import registry

    loads: list[str] = []

    class FakeEntryPoint:
        name = "probe"
        value = "probe_pkg:CHARACTERISTIC"

        def load(self) -> Characteristic:
            loads.append(self.name)
            return Characteristic(name="entry_probe", label="entry probe", compute=_nan_score)

    def entry_points(*, group: str) -> list[FakeEntryPoint]:
        assert group == "pytest_hevval.characteristics"
        return [FakeEntryPoint()]

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    monkeypatch.setattr(registry, "_entry_points_loaded", False)
    registry.load_entry_points()
    registry.load_entry_points()
    assert loads == ["probe"]
    assert registry.get_characteristic("entry_probe").label == "entry probe"


def test_unknown_characteristic_gets_did_you_mean() -> None:
    from pytest_hevval.core.registry import get_characteristic

    with pytest.raises(CharacteristicError, match="did you mean 'error_std'"):
        get_characteristic("error_sd")


def test_compare_reads_stored_schema_1_against_schema_2(tmp_path: Path) -> None:
    from pytest_hevval.cli import main

    output = tmp_path / "compare.json"
    code = main(
        [
            "compare",
            str(DATA / "schema1_camry_hwfet.json"),
            str(DATA / "schema2_camry_hwfet.json"),
            "--format",
            "json",
            "--output",
            str(output),
        ]
    )
    assert code == 0
    signals = json.loads(output.read_text())["comparison"]["specs"][0]["signals"]
    assert [s["path"] for s in signals] == ["FC_cum", "FC_cum/FC_rate", "v"]
    for signal in signals:
        assert list(signal["lambdas"]) == list(PAPER_CHARACTERISTICS)
        assert all(d["delta"] == 0 for d in signal["lambdas"].values())

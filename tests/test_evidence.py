"""The evidence record: valid against its published schema from every source, and enough to
re-run the example and reproduce every verdict."""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from pathlib import Path

import jsonschema
import pytest

from pytest_hevval.cli import main
from pytest_hevval.data.digest import file_digest
from pytest_hevval.report.evidence import schema
from pytest_hevval.scoring.run import RunOptions, run_specs
from pytest_hevval.spec.load import load_specs
from tests.test_plugin import write_data
from tests.test_requirements import SPEC as PACK_SPEC

pytest_plugins = ["pytester"]

EXAMPLE = Path(__file__).resolve().parent.parent / "example_project"
#: A small part of the example: one Camry cycle and one i3 trip, both models run as callables.
PART = ("specs/camry-us06.hevval.yaml", "specs/i3-A02-motorway-v2.hevval.yaml")


@pytest.fixture(scope="module")
def example(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the part of the example project the record is made from."""
    root = tmp_path_factory.mktemp("example")
    for folder in ("models", "data/camry", "specs"):
        (root / folder).mkdir(parents=True)
    for name in ("models/__init__.py", "models/camry.py", "models/camry_params.json"):
        shutil.copy(EXAMPLE / name, root / name)
    for name in ("models/ev.py", "models/ev_params.json", *PART):
        shutil.copy(EXAMPLE / name, root / name)
    shutil.copy(EXAMPLE / "data/camry/61811014.parquet", root / "data/camry")
    (root / "data/i3").mkdir()
    shutil.copy(EXAMPLE / "data/i3/TripA02.parquet", root / "data/i3")
    return root


def _validate(record: object) -> None:
    jsonschema.Draft202012Validator.check_schema(schema())
    jsonschema.validate(record, schema(), cls=jsonschema.Draft202012Validator)


def test_example_record_validates_and_reproduces_every_verdict(
    example: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(example)
    main(["run", *PART, "--no-history", "--json", "run.json", "--model-version", "v2"])
    assert main(["evidence", "run.json", "--output", "evidence.json"]) == 0
    record = json.loads((example / "evidence.json").read_text())
    _validate(record)
    assert record["source"] == "hevval run"
    assert record["run"]["model_version"] == "v2"
    assert {"python", "numpy", "pandas"} <= {k for k, v in record["environment"].items() if v}
    assert record["requirements"]["EV-ENERGY-01"] == [
        {
            "spec": "specs/i3-A02-motorway-v2.hevval.yaml",
            "items": [
                "E_batt",
                "E_batt/P_batt",
                "E_batt/P_batt/I_batt",
                "E_batt/P_batt/I_batt/T_mot",
                "E_batt/P_batt/U_batt",
            ],
        }
    ]
    # Re-run from the record's facts alone: every file is the one the record names, then
    # every verdict comes out again.
    for entry in record["specs"]:
        spec_file = example / entry["key"]
        assert hashlib.sha256(spec_file.read_bytes()).hexdigest() == entry["spec_sha256"]
        reference = entry["reference"]
        algorithm = "sha256" if reference["hash"] == "sha256" else "fast"
        assert file_digest(str(example / reference["path"]), algorithm) == {
            "hash": reference["hash"],
            "digest": reference["digest"],
        }
        model = entry["model"]
        assert model["kind"] == "callable"
        module = (example / model["module_file"]).read_bytes()
        assert hashlib.sha256(module).hexdigest() == model["module_sha256"]
        assert entry["runtime"]["wall_s"][0] > 0
        [again] = run_specs(load_specs(spec_file), RunOptions(rootdir=example))
        result = again.result
        verdict = entry["verdict"]
        assert result.passed == verdict["passed"]
        assert result.phi == pytest.approx(verdict["phi"], rel=0, abs=1e-12)
        assert result.phi_interval is not None
        assert (result.phi_interval.low, result.phi_interval.high) == pytest.approx(
            (verdict["phi_interval"]["low"], verdict["phi_interval"]["high"]), abs=1e-12
        )
        for signal in entry["signals"]:
            scored = result.signal(signal["path"])
            assert scored.passed == signal["passed"]
            for name, value in signal["lambdas"].items():
                assert math.isclose(scored.lambdas[name], value, abs_tol=1e-12)
    run = json.loads((example / "run.json").read_text())
    assert [s["verdict"]["passed"] for s in record["specs"]] == [s["passed"] for s in run["specs"]]


def test_pytest_report_and_history_record_give_valid_records(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytester.makefile(".hevval.yaml", pack=PACK_SPEC)
    write_data(pytester.path)
    pytester.runpytest(
        "--hevval", "--hevval-history", "--hevval-report=evidence", "--hevval-model-version=v3"
    ).assert_outcomes(passed=6)
    from_pytest = json.loads((pytester.path / ".hevval/report/evidence.json").read_text())
    _validate(from_pytest)
    assert from_pytest["source"] == "pytest run"
    assert from_pytest["run"]["model_version"] == "v3"
    [spec] = from_pytest["specs"]
    assert spec["runtime"] is None
    assert spec["runtime_note"].startswith("the model is exported files")
    assert spec["model"]["digest"]
    monkeypatch.chdir(pytester.path)
    capsys.readouterr()
    assert main(["evidence"]) == 0
    from_history = json.loads(capsys.readouterr().out)
    _validate(from_history)
    assert from_history["source"] == "history record"
    assert from_history["specs"] == from_pytest["specs"]
    assert from_history["requirements"]["CUR-4"] == [
        {"spec": "pack.hevval.yaml", "items": ["E/P/I"]}
    ]


def test_a_broken_record_fails_the_schema(pytester: pytest.Pytester) -> None:
    pytester.makefile(".hevval.yaml", pack=PACK_SPEC)
    write_data(pytester.path)
    pytester.runpytest("--hevval", "--hevval-report=evidence")
    record = json.loads((pytester.path / ".hevval/report/evidence.json").read_text())
    del record["specs"][0]["verdict"]["phi"]
    with pytest.raises(jsonschema.ValidationError, match="'phi' is a required property"):
        _validate(record)


def test_evidence_of_a_missing_run_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["evidence", "nowhere.json"]) == 2
    err = capsys.readouterr().err
    assert "nowhere.json: no such file" in err
    assert "Traceback" not in err

"""Requirements on specs and signals: loading, JUnit properties as importers read them,
reports, history records and the ``hevval trace`` view."""

from __future__ import annotations

import csv
import io
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from pytest_hevval.cli import main
from pytest_hevval.errors import HevvalError, SpecError
from pytest_hevval.report.trace import read_requirement_list, render_trace, trace_rows
from pytest_hevval.results.spec_result import SpecResult
from pytest_hevval.spec.load import parse_spec_text
from tests.test_plugin import TREE_SPEC, write_data

pytest_plugins = ["pytester"]

#: The pack spec of test_plugin with requirements on the spec, a set root and a leaf.
SPEC = (
    TREE_SPEC.replace("min_phi: 0.5\n", "min_phi: 0.5\nrequirements: [PACK-1]\n")
    .replace("    unit: Wh\n", "    unit: Wh\n    requirements: [ENERGY-2, ENERGY-3]\n")
    .replace(
        "{signal: I, unit: A, alpha: 0.5}",
        "{signal: I, unit: A, alpha: 0.5, requirements: [CUR-4]}",
    )
)


def _load(text: str) -> object:
    return parse_spec_text(text, Path("pack.hevval.yaml"))


def test_requirements_are_inherited_down_the_tree_and_merged() -> None:
    spec = _load(SPEC)
    found = {"/".join(path): node.requirements for _, path, node in spec.walk()}  # type: ignore[attr-defined]
    assert spec.requirements == ("PACK-1",)  # type: ignore[attr-defined]
    assert found == {
        "E": ("PACK-1", "ENERGY-2", "ENERGY-3"),
        "E/P": ("PACK-1", "ENERGY-2", "ENERGY-3"),
        "E/P/V": ("PACK-1", "ENERGY-2", "ENERGY-3"),
        "E/P/I": ("PACK-1", "ENERGY-2", "ENERGY-3", "CUR-4"),
        "speed": ("PACK-1",),
    }


@pytest.mark.parametrize(
    ("replace", "by", "message"),
    [
        (
            "requirements: [CUR-4]",
            "requirements: [CUR-4, CUR-4]",
            "pack.hevval.yaml:20: sets[0].children[0].children[1].requirements[1]: duplicate "
            "requirement 'CUR-4' (first given at line 20)",
        ),
        (
            "requirements: [CUR-4]",
            "requirements: [ENERGY-2]",
            "pack.hevval.yaml:20: sets[0].children[0].children[1].requirements[0]: duplicate "
            "requirement 'ENERGY-2' (first given at line 13, and inherited here)",
        ),
        (
            "requirements: [CUR-4]",
            'requirements: [""]',
            "pack.hevval.yaml:20: sets[0].children[0].children[1].requirements[0]: must be a "
            "non-empty requirement ID",
        ),
        (
            "requirements: [PACK-1]",
            'requirements: ["A,B"]',
            "pack.hevval.yaml:7: requirements[0]: must be a non-empty requirement ID",
        ),
        (
            "requirements: [PACK-1]",
            "requirements: {PACK-1: yes}",
            "pack.hevval.yaml:7: requirements: must be a list of requirement IDs",
        ),
    ],
)
def test_bad_requirements_name_file_line_and_key(replace: str, by: str, message: str) -> None:
    with pytest.raises(SpecError) as raised:
        _load(SPEC.replace(replace, by))
    assert str(raised.value).startswith(message)


def _xray_links(junit: Path) -> dict[str, tuple[list[str], list[str], str]]:
    """What an importer reads per test case: Xray's comma-separated ``requirements``, the
    generic one-per-ID ``requirement`` properties, and the outcome."""
    links = {}
    for case in ET.parse(junit).iter("testcase"):
        properties = [(p.get("name"), p.get("value") or "") for p in case.iter("property")]
        xray = [v for n, v in properties if n == "requirements"]
        assert len(xray) <= 1
        keys = [k.strip() for k in xray[0].split(",")] if xray else []
        generic = [v for n, v in properties if n == "requirement"]
        outcome = "failed" if case.find("failure") is not None else "passed"
        links[str(case.get("name"))] = (keys, generic, outcome)
    return links


@pytest.mark.parametrize("parallel", [False, True], ids=["serial", "xdist"])
def test_junit_carries_requirements_as_importers_read_them(
    pytester: pytest.Pytester, parallel: bool
) -> None:
    pytester.makefile(".hevval.yaml", pack=SPEC)
    write_data(pytester.path, fault="leaf")
    extra = ["-p", "xdist", "-n", "2"] if parallel else []
    pytester.runpytest("--hevval", "--junitxml=out.xml", *extra)
    links = _xray_links(pytester.path / "out.xml")
    assert links["Phi"][0] == ["PACK-1"]
    assert links["speed"][:2] == (["PACK-1"], ["PACK-1"])
    assert links["E/P/I"][0] == ["PACK-1", "ENERGY-2", "ENERGY-3", "CUR-4"]
    assert links["E/P/I"][1] == links["E/P/I"][0]
    assert links["E/P/I"][2] == "failed"  # the leaf's fault: the requirement is not met
    assert links["speed"][2] == "passed"


def test_reports_and_history_carry_requirements(pytester: pytest.Pytester) -> None:
    pytester.makefile(".hevval.yaml", pack=SPEC)
    write_data(pytester.path, fault="leaf")
    pytester.runpytest(
        "--hevval", "--hevval-history", "--hevval-report=html,json,md", "--hevval-model-version=v7"
    )
    report = pytester.path / ".hevval" / "report"
    spec = json.loads((report / "report.json").read_text())["specs"][0]
    assert spec["requirements"] == ["PACK-1"]
    assert {s["path"]: s.get("requirements") for s in spec["signals"]}["E/P/I"] == [
        "PACK-1",
        "ENERGY-2",
        "ENERGY-3",
        "CUR-4",
    ]
    markdown = (report / "report.md").read_text()
    assert "| CUR-4 | FAIL | pack | E/P/I |" in markdown
    assert "4 requirements: 0 pass, 4 fail" in markdown
    page = (report / "report.html").read_text()
    assert '<section class="card" id="requirements">' in page
    assert '<td class="mono">ENERGY-2</td>' in page
    [record_file] = (pytester.path / ".hevval" / "history").glob("*.json")
    record = json.loads(record_file.read_text())
    recorded = record["specs"][0]
    assert recorded["requirements"] == ["PACK-1"]
    assert {s["path"]: s["requirements"] for s in recorded["signals"]}["speed"] == ["PACK-1"]


def test_trace_command_lists_verdicts_and_uncovered_requirements(
    pytester: pytest.Pytester, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    pytester.makefile(".hevval.yaml", pack=SPEC)
    write_data(pytester.path, fault="leaf")
    pytester.runpytest("--hevval", "--hevval-history", "--hevval-model-version=v7")
    (pytester.path / "team.csv").write_text(
        "id,title\nPACK-1,the pack\nCUR-4,current\nSPEED-9,never verified\n"
    )
    monkeypatch.chdir(pytester.path)
    capsys.readouterr()
    code = main(["trace", "--requirements", "team.csv", "--format", "csv"])
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert code == 1
    by_id = {row["requirement"]: row for row in rows}
    assert by_id["CUR-4"]["status"] == "FAIL"
    assert by_id["CUR-4"]["items"] == "E/P/I"
    assert by_id["CUR-4"]["model version"] == "v7"
    assert by_id["CUR-4"]["data"].startswith("data/ref.csv (")
    assert by_id["SPEED-9"]["status"] == "UNCOVERED"
    assert by_id["ENERGY-2 (not in the list)"]["items"] == "E, E/P, E/P/V, E/P/I"
    assert [row["requirement"] for row in rows][:3] == ["PACK-1", "CUR-4", "SPEED-9"]
    assert main(["trace", "--format", "json"]) == 1
    document = json.loads(capsys.readouterr().out)
    assert document["summary"] == "4 requirements: 0 pass, 4 fail"
    phi_interval = document["rows"][0]["phi_interval"]
    assert phi_interval["low"] <= document["rows"][0]["phi"] <= phi_interval["high"]
    for fmt, marker in (("table", "PACK-1"), ("md", "| PACK-1 |"), ("html", "<td>PACK-1</td>")):
        assert main(["trace", "--format", fmt]) == 1
        assert marker in capsys.readouterr().out
    # A later run of another spec only: each spec keeps its own latest verdict and version.
    pytester.makefile(".hevval.yaml", other=SPEC.replace("name: pack", "name: other"))
    pytester.runpytest(
        "--hevval", "other.hevval.yaml", "--hevval-history", "--hevval-model-version=v8"
    )
    capsys.readouterr()
    main(["trace", "--format", "json"])
    versions = {
        (row["spec"], row["model_version"])
        for row in json.loads(capsys.readouterr().out)["rows"]
        if row["requirement"] == "PACK-1"
    }
    assert versions == {("pack", "v7"), ("other", "v8")}
    main(["trace", "history:latest", "--format", "json"])
    assert {row["spec"] for row in json.loads(capsys.readouterr().out)["rows"]} == {"other"}


def test_trace_without_requirements_says_so(
    pytester: pytest.Pytester, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    pytester.makefile(".hevval.yaml", pack=TREE_SPEC)
    write_data(pytester.path)
    pytester.runpytest("--hevval", "--hevval-history")
    monkeypatch.chdir(pytester.path)
    assert main(["trace"]) == 1
    assert "names requirements" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("A-1\nA-1\n", "team.txt:2: requirement 'A-1' is listed twice (first at line 1)"),
        ("A-1\nB\x07\n", "team.txt:2: must be a non-empty requirement ID"),
        ("# only a comment\n\n", "team.txt: the requirement list holds no ID"),
    ],
)
def test_bad_requirement_list_names_file_and_line(
    tmp_path: Path, text: str, message: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    Path("team.txt").write_text(text)
    with pytest.raises(HevvalError) as raised:
        read_requirement_list("team.txt")
    assert str(raised.value).startswith(message)


def test_requirement_list_reads_plain_lines_and_csv(tmp_path: Path) -> None:
    plain = tmp_path / "team.txt"
    plain.write_text("# ours\nA-1\n\nB-2\n")
    assert read_requirement_list(plain) == ["A-1", "B-2"]
    table = tmp_path / "team.csv"
    table.write_text('requirement,title\nA-1,"first, with a comma"\nB-2,second\n')
    assert read_requirement_list(table) == ["A-1", "B-2"]


#: The fields a signal's result needs besides its path (λ, errors, place in the tree).
_SIGNAL = {"set": 1, "level": 1, "alpha": 1.0, "lambdas": [1.0], "lag_s": 0.0}
_SIGNAL |= {"peak_correlation": 1.0, "mae": 0.0, "rms": 0.0}
_MISS = {"characteristic": "mae", "value": 0.5, "threshold": 0.9}


def test_trace_rows_of_a_whole_spec_requirement_judge_the_whole_spec() -> None:
    spec = {
        "name": "s",
        "spec": "s.hevval.yaml",
        "phi": 0.95,
        "passed": False,
        "requirements": ["R-1"],
        "signals": [
            {**_SIGNAL, "path": "a", "requirements": ["R-1", "R-2"]},
            {**_SIGNAL, "path": "b", "requirements": ["R-1"], "failures": [_MISS]},
        ],
        "data": {"reference": {"path": "ref.csv", "hash": "sha256", "digest": "ab"}},
    }
    rows = trace_rows([SpecResult.from_dict(spec)], model_version="v1")
    assert [(r.requirement, r.status, r.items) for r in rows] == [
        ("R-1", "FAIL", "whole spec (Φ and every signal)"),
        ("R-2", "PASS", "a"),
    ]
    assert "ref.csv (sha256:ab)" in render_trace(rows, "table")
    assert render_trace(rows[:1], "table").endswith("\n1 requirement: 0 pass, 1 fail\n")


@pytest.mark.parametrize("parallel", [False, True], ids=["serial", "xdist"])
def test_a_campaign_gate_verifies_the_specs_requirements(
    pytester: pytest.Pytester, parallel: bool
) -> None:
    from tests.test_campaign import write_campaign

    write_campaign(pytester.path)
    spec = pytester.path / "fleet.hevval.yaml"
    spec.write_text(spec.read_text().replace("sets:\n", "requirements: [FLEET-1]\nsets:\n"))
    extra = ["-p", "xdist", "-n", "2"] if parallel else []
    pytester.runpytest("--hevval", "--hevval-no-history", "--junitxml=out.xml", *extra)
    links = _xray_links(pytester.path / "out.xml")
    assert links["campaign"][:2] == (["FLEET-1"], ["FLEET-1"])
    assert links["Phi"][0] == ["FLEET-1"]

"""Closing the loop on the example's real i3 trips, as docs/closing-the-loop.md runs it.

Model v1 fails; the residual diagnosis of its battery power names the effect v1 lacks, from
the measured channels; model v2 adds that effect and its energy error drops; ``hevval compare``
pairs the v1 run with the v2 run. On the unseen trip B24 (section 5), model v1 changed exactly
as the diagnosis prints scores what the diagnosis predicted. Also the spec pairing of
``compare`` on its own.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest
import yaml

from pytest_hevval.cli import main as cli_main
from pytest_hevval.history import compare
from tests.example_cli import EXAMPLE, run_in_example
from tests.recorded_runs import recorded

B03_V1 = "specs/i3-B03-winter-v1.hevval.yaml"
B03_V2 = "specs/i3-B03-winter-v2.hevval.yaml"
A12_V1 = "specs/i3-A12-hills-v1.hevval.yaml"
A12_V2 = "specs/i3-A12-hills-v2.hevval.yaml"
B24_V1 = "walks/i3-B24-winter-v1.hevval.yaml"
B24_FIXED = "walks/i3-B24-winter-v1-fixed.hevval.yaml"
POWER = "E_batt/P_batt"
DOC = EXAMPLE.parent / "docs" / "closing-the-loop.md"
FULL_LOG = Path(__file__).resolve().parent / "data" / "i3" / "TripB03_full.parquet"


def _without_candidates(spec: Path, target: Path) -> None:
    """A copy of ``spec`` with no declared candidates, so only measured channels are tried."""
    kept: list[str] = []
    skipping = False
    for line in spec.read_text(encoding="utf-8").splitlines():
        if line.startswith("candidates:"):
            skipping = True
            continue
        if skipping and line[:1] not in (" ", "#", ""):
            skipping = False
        if not skipping:
            kept.append(line)
    text = "\n".join(kept) + "\n"
    # The copy lives elsewhere, so its data path must not be relative to the spec's folder.
    text = text.replace("path: ../data/", f"path: {EXAMPLE / 'data'}/")
    target.write_text(text, encoding="utf-8")


@pytest.fixture(scope="module")
def loop(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Run the loop's commands; return the JSON file each one wrote, by name."""
    out = tmp_path_factory.mktemp("loop")
    channels_only = out / "b03-v1-channels-only.yaml"
    _without_candidates(EXAMPLE / B03_V1, channels_only)
    # The same trip's full log: the heater is measured five ways there.
    full_log = out / "b03-v1-full-log.yaml"
    full_log.write_text(
        (EXAMPLE / B03_V1)
        .read_text(encoding="utf-8")
        .replace("../data/i3/TripB03.parquet", str(FULL_LOG)),
        encoding="utf-8",
    )
    run = ["--no-history", "--quiet", "--json"]
    commands = {
        "b03-v1": ["run", B03_V1, *run, str(out / "b03-v1.json")],
        "b03-v2": ["run", B03_V2, *run, str(out / "b03-v2.json")],
        "a12": ["run", A12_V1, A12_V2, *run, str(out / "a12.json")],
        "b03-diagnosis": ["diagnose", B03_V1, "--signal", POWER],
        "b03-declared": ["diagnose", B03_V1, "--signal", POWER, "--no-channels"],
        "b03-channels": ["diagnose", str(channels_only), "--signal", POWER],
        "b03-full": ["diagnose", str(full_log), "--signal", POWER],
        "a12-declared": ["diagnose", A12_V1, "--signal", POWER, "--no-channels"],
    }
    for name, argv in commands.items():
        if argv[0] == "diagnose":
            argv += ["--json", str(out / f"{name}.json")]
    # One process runs every command (see tests/example_cli.py).
    codes, _ = run_in_example(commands)
    # `hevval run` exits 1 when a gate fails, which model v1 does on purpose.
    assert codes == {name: 1 if name in ("b03-v1", "b03-v2", "a12") else 0 for name in commands}
    return {name: out / f"{name}.json" for name in commands}


def _read(path: Path) -> dict[str, Any]:
    document: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return document


def _top(diagnosis: Mapping[str, Any]) -> Mapping[str, Any]:
    """The diagnosis' first finding: its first relevant effect."""
    return next(e for e in diagnosis["effects"] if e["relevant"])


def _signal(spec: Mapping[str, Any], path: str) -> Mapping[str, Any]:
    return next(s for s in spec["signals"] if s["path"] == path)


# -- B03, winter: the heater -------------------------------------------------------------------


def test_b03_v1_fails_on_energy_while_battery_power_passes(loop: dict[str, Path]) -> None:
    v1 = _read(loop["b03-v1"])
    assert v1["passed"] is False
    assert _signal(v1, "E_batt")["origin"] is True
    # The power passes its gates, so the error appears only where it adds up: the diagnosis
    # has to look one level down, where the load shows at each instant.
    assert _signal(v1, POWER)["passed"] is True


def test_b03_diagnosis_names_the_heating_load(loop: dict[str, Path]) -> None:
    for name in ("b03-diagnosis", "b03-declared"):
        found = _read(loop[name])
        top = _top(found)
        assert top["name"] == "heating_aircon_kw", (name, top)
        # The heater runs off the traction battery: about 1 kW more battery power per kW of
        # logged heater power is what physics expects, and the interval must allow it.
        low, high = top["interval"]
        assert 0.0 < low < 1.0 < high, (name, top["interval"])


def test_b03_measured_channel_alone_points_at_the_heater(loop: dict[str, Path]) -> None:
    found = _read(loop["b03-channels"])
    assert not any(c["kind"] == "declared" for c in found["candidates"])
    top = _top(found)
    assert (top["name"], top["kind"]) == ("Heating Power CAN [kW]", "channel")
    assert top["interval"][0] > 0.0


def test_b03_full_log_reports_the_heater_channels_as_one_effect(loop: dict[str, Path]) -> None:
    """Five channels measure the heater in the full log; fitted side by side they split it with
    opposite signs and none is credited. As one effect, it is the first finding."""
    found = _read(loop["b03-full"])
    top = _top(found)
    heater = {
        "heating_aircon_kw",
        "Heating Power CAN [kW]",
        "Heating Power LIN [W]",
        "Heater Current [A]",
        "Requested Heating Power [W]",
    }
    assert top["name"] in heater
    assert heater <= {top["name"], *top["members"]}
    assert top["coefficient"] > 0.0
    assert top["interval"][0] > 0.0
    # No member of the heater group is offered again on its own.
    assert not any(e["name"] in heater for e in found["effects"] if e is not top)
    # The effects' shares partition what they explain together.
    shares = [e["share"] for e in found["effects"]]
    assert all(s >= 0.0 for s in shares)
    assert sum(shares) <= 1.0
    # Only the heater is a finding: the warming battery, which mimics it, is not one of its own.
    assert [e["name"] for e in found["effects"] if e["relevant"]] == [top["name"]]


def test_b03_v2_halves_the_energy_error_and_compare_pairs_the_runs(
    loop: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    before, after = str(loop["b03-v1"]), str(loop["b03-v2"])
    assert cli_main(["compare", before, after]) == 0
    table = capsys.readouterr().out
    assert f"comparing {B03_V1} (before) with {B03_V2} (after)" in table.splitlines()[1]
    assert cli_main(["compare", before, after, "--format", "json"]) == 0
    comparison = json.loads(capsys.readouterr().out)["comparison"]
    (spec,) = comparison["specs"]
    assert (spec["before_spec"], spec["spec"], spec["matched_by"]) == (B03_V1, B03_V2, "single")
    energy = next(s for s in spec["signals"] if s["path"] == "E_batt")
    mae = energy["errors"]["mae"]
    assert mae["after"] < 0.7 * mae["before"], mae
    assert energy["lambdas"]["mae"]["after"] > energy["lambdas"]["mae"]["before"]
    assert energy["passed"] == {"before": False, "after": True}
    assert spec["phi"]["after"] > spec["phi"]["before"]


# -- A12, hills: the climb ---------------------------------------------------------------------


def test_a12_declared_climb_rate_explains_the_power_residual(loop: dict[str, Path]) -> None:
    found = _read(loop["a12-declared"])
    top = _top(found)
    assert top["name"] == "climb_rate_m_s"
    # kW of battery power per m/s of climb: m·g is about 13.6 kW per m/s for this car.
    assert top["interval"][0] > 5.0


def test_a12_v2_with_grade_lowers_the_energy_error(loop: dict[str, Path]) -> None:
    v1, v2 = _read(loop["a12"])["specs"]
    assert (v1["spec"], v2["spec"]) == (A12_V1, A12_V2)
    assert _signal(v2, "E_batt")["mae"] < 0.7 * _signal(v1, "E_batt")["mae"]


# -- B24, an unseen winter trip: the printed fix, applied to the model -----------------------


@pytest.fixture(scope="module")
def b24(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Model v1 and model v1 with the printed fix on B24, and one diagnosis of v1's battery
    power; the JSON file each wrote, by name."""
    out = tmp_path_factory.mktemp("b24")
    run = ["--no-history", "--quiet", "--json"]
    commands = {
        "v1": ["run", B24_V1, *run, str(out / "v1.json")],
        "fixed": ["run", B24_FIXED, *run, str(out / "fixed.json")],
        "diagnosis": ["diagnose", B24_V1, "--signal", POWER, "--json", str(out / "dx.json")],
    }
    codes, _ = run_in_example(commands)
    # Both runs fail on the terminal voltage, which the heater does not explain.
    assert codes == {"v1": 1, "fixed": 1, "diagnosis": 0}
    return {"v1": out / "v1.json", "fixed": out / "fixed.json", "diagnosis": out / "dx.json"}


def _model_params(spec: str) -> dict[str, Any]:
    document = yaml.safe_load((EXAMPLE / spec).read_text(encoding="utf-8"))
    params: dict[str, Any] = document["model"]["params"]
    return params


def test_b24_v1_fails_and_the_heater_is_the_first_finding(b24: dict[str, Path]) -> None:
    (v1,) = _read(b24["v1"])["specs"]
    assert v1["passed"] is False
    # The SoC falls too slowly: the model draws too little charge.
    assert _signal(v1, "SoC")["passed"] is False
    top = _top(_read(b24["diagnosis"]))
    assert top["name"] == "heating_aircon_kw"
    assert top["coefficient"] > 0.0
    assert top["interval"][0] > 0.0


def test_b24_fixed_spec_is_v1_changed_exactly_as_printed(b24: dict[str, Path]) -> None:
    """The fixed spec's parameters are the printed `--try` term's numbers (six significant
    digits), and the doc quotes that term: doc, spec and diagnosis cannot drift apart."""
    top = _top(_read(b24["diagnosis"]))
    gain, constant_kw = float(f"{top['fix_coefficient']:.6g}"), float(f"{top['fix_constant']:.6g}")
    fitted = json.loads((EXAMPLE / "models" / "ev_params.json").read_text(encoding="utf-8"))
    base_load_w = fitted["versions"]["1"]["params"]["base_load_w"]
    assert _model_params(B24_V1) == {"version": 1}
    params = _model_params(B24_FIXED)
    assert params["version"] == 1
    assert params["heater_aircon_gain"] == gain
    assert params["base_load_w"] == pytest.approx(base_load_w + 1e3 * constant_kw, abs=1e-6)
    sign = "-" if constant_kw < 0 else "+"
    term = f"{gain:g} * heating_aircon_kw {sign} {abs(constant_kw):g}"
    doc = DOC.read_text(encoding="utf-8")
    assert f"--try '{term}'" in doc
    assert f"heater_aircon_gain: {gain:g}, base_load_w: {params['base_load_w']}" in doc
    # What the diagnosis predicts, as the doc quotes it.
    assert top["then"] in doc


def test_b24_fixed_model_scores_what_the_diagnosis_predicted(b24: dict[str, Path]) -> None:
    top = _top(_read(b24["diagnosis"]))
    (v1,) = _read(b24["v1"])["specs"]
    (fixed,) = _read(b24["fixed"])["specs"]
    predicted = {POWER: top["predicted"]}
    predicted.update({a["signal"]: a["predicted"] for a in top["above"]})
    assert set(predicted) == {POWER, "E_batt"}
    for path, expected in predicted.items():
        for key in ("mae", "rms"):
            before = _signal(v1, path)["lambdas"][key]
            after = _signal(fixed, path)["lambdas"][key]
            # The doc says the two agree to four decimals.
            assert abs(after - expected[key]) < 1e-4, (path, key, after, expected[key])
            assert after > before, (path, key, before, after)


def test_walks_stay_out_of_the_example_test_run() -> None:
    """`pytest --hevval` in the example collects specs/ only, and the campaign's pattern does
    not take in the walks' extra trip, so the README's count stays what it says."""
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "--hevval",
            "--collect-only",
            "-q",
            "-p",
            "no:cacheprovider",
        ],
        cwd=EXAMPLE,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    ids = [line for line in done.stdout.splitlines() if "::" in line]
    assert ids
    assert not [i for i in ids if i.startswith("walks/") or "TripB24" in i]
    readme = (EXAMPLE / "README.md").read_text(encoding="utf-8")
    counted = re.search(r"spec files, \d+ pass; (\d+) items", readme)
    assert counted is not None
    assert len(ids) == int(counted.group(1))


# -- compare: which spec is compared with which ------------------------------------------------


def _spec(path: str | None, name: str, phi: float, mae: float = 0.9) -> dict[str, Any]:
    spec: dict[str, Any] = {
        "name": name,
        "phi": phi,
        "passed": phi >= 0.9,
        "signals": [{"path": "E", "name": "E", "lambdas": [1.0, 1.0, mae, 1.0, 1.0, 1.0, 1.0]}],
    }
    if path is not None:
        spec["spec"] = path
    return spec


def test_one_spec_per_side_pairs_whatever_the_path_only_when_asked() -> None:
    before = [_spec("specs/trip-v1.yaml", "trip, model v1", 0.90)]
    after = [_spec("specs/trip-v2.yaml", "trip, model v2", 0.95)]
    (pair,) = compare(recorded(after), recorded(before), pair_single=True).specs
    assert (pair.before_key, pair.key, pair.matched_by) == (
        "specs/trip-v1.yaml",
        "specs/trip-v2.yaml",
        "single",
    )
    assert pair.phi.delta == pytest.approx(0.05)
    assert pair.pairing == (
        "comparing specs/trip-v1.yaml (before) with specs/trip-v2.yaml (after): "
        "the only spec on each side"
    )
    # A gate comparing one spec of this run with a history record must not pair strangers.
    plain = compare(recorded(after), recorded(before))
    assert plain.specs == ()
    assert (plain.added_specs, plain.removed_specs) == (
        ("specs/trip-v2.yaml",),
        ("specs/trip-v1.yaml",),
    )


def test_several_specs_match_by_path_then_by_unique_name() -> None:
    before = [
        _spec("specs/a.yaml", "A", 0.91),
        _spec("specs/old-b.yaml", "B", 0.92),
        _spec("specs/c1.yaml", "C", 0.93),
        _spec("specs/c2.yaml", "C", 0.94),
    ]
    after = [
        _spec("specs/a.yaml", "A renamed", 0.95),
        _spec("specs/new-b.yaml", "B", 0.96),
        _spec("specs/c3.yaml", "C", 0.97),
    ]
    comparison = compare(recorded(after), recorded(before), pair_single=True)
    pairs = {s.key: (s.before_key, s.matched_by) for s in comparison.specs}
    assert pairs == {
        "specs/a.yaml": ("specs/a.yaml", "path"),
        "specs/new-b.yaml": ("specs/old-b.yaml", "name"),
    }
    # Two baseline specs are called "C": a name that does not say which is no match.
    assert comparison.added_specs == ("specs/c3.yaml",)
    assert comparison.removed_specs == ("specs/c1.yaml", "specs/c2.yaml")
    note = "comparing specs/old-b.yaml (before) with specs/new-b.yaml (after): the same spec name"
    assert comparison.pairings == (f"{note} 'B'",)


def test_same_spec_on_both_sides_needs_no_pairing_note() -> None:
    before = {"schema_version": 1, "specs": [_spec("specs/a.yaml", "A", 0.91)]}
    after = {"schema_version": 1, "specs": [_spec("specs/a.yaml", "A", 0.95, mae=0.8)]}
    comparison = compare(recorded(after), recorded(before), pair_single=True)
    (pair,) = comparison.specs
    assert (pair.matched_by, pair.pairing, comparison.pairings) == ("path", None, ())
    assert pair.signals[0].field("mae").delta == pytest.approx(-0.1)


def test_markdown_names_both_specs_under_the_title(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for side, path, phi in (("before", "specs/x|v1.yaml", 0.9), ("after", "specs/x|v2.yaml", 0.95)):
        run = {"schema_version": 1, "specs": [_spec(path, f"x {side}", phi)]}
        (tmp_path / f"{side}.json").write_text(json.dumps(run), encoding="utf-8")
    argv = [str(tmp_path / "before.json"), str(tmp_path / "after.json"), "--format", "md"]
    assert cli_main(["compare", *argv]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "## hevval compare `before.json` → `after.json`"
    assert lines[1:3] == [
        "",
        r"comparing specs/x\|v1.yaml (before) with specs/x\|v2.yaml (after): "
        "the only spec on each side",
    ]

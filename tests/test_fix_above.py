"""The printed fix and the signals above the diagnosed one: an energy the model integrates from
its power is predicted and re-scored with the fix integrated the same way, and the prediction
is what the example's model v1 scores once the fix is in its parameters."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from pytest_hevval.scoring.fixes import running_integral
from tests.example_cli import EXAMPLE, run_in_example

B03_V1 = EXAMPLE / "specs" / "i3-B03-winter-v1.hevval.yaml"
POWER = "E_batt/P_batt"
ENERGY = "E_batt"


# -- detecting the running integral -------------------------------------------------------------


def _signals(seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    # Uneven steps: the integral is taken over the times, not the sample count.
    time = np.cumsum(rng.uniform(0.05, 0.15, 3000))
    power = 10 + np.convolve(rng.normal(size=time.size), np.ones(40) / 40, "same") * 30
    return time, power


def test_a_cumulative_trapezoid_is_found_with_its_factor() -> None:
    time, power = _signals()
    steps = 0.5 * (power[1:] + power[:-1]) * np.diff(time)
    energy = 5.0 + np.concatenate(([0.0], np.cumsum(steps))) / 3600.0
    factor = running_integral(energy, power, time)
    assert factor == pytest.approx(1.0 / 3600.0, rel=1e-9)
    # Counted the other way round (a charge drawn, negative), it is still one.
    assert running_integral(-energy, power, time) == pytest.approx(-1.0 / 3600.0, rel=1e-9)


def test_an_unrelated_parent_is_not_a_running_integral() -> None:
    time, power = _signals()
    # A parent the child drives but does not add up to: a product with another signal, the
    # running sum of a different signal, and the child itself.
    _, other = _signals(seed=9)
    assert running_integral(power * other, power, time) is None
    steps = 0.5 * (other[1:] + other[:-1]) * np.diff(time)
    assert running_integral(np.concatenate(([0.0], np.cumsum(steps))), power, time) is None
    assert running_integral(power, power, time) is None
    # Nor is one that matches only up to a drift larger than rounding.
    steps = 0.5 * (power[1:] + power[:-1]) * np.diff(time)
    drifting = np.concatenate(([0.0], np.cumsum(steps))) * (1 + 0.05 * np.sin(time / 50))
    assert running_integral(drifting, power, time) is None
    # Constant or non-finite series say nothing.
    assert running_integral(np.ones_like(time), power, time) is None
    gap = power.copy()
    gap[10] = np.nan
    assert running_integral(power, gap, time) is None


# -- the example's winter trip, end to end ------------------------------------------------------


def _fixed_spec(target: Path, first: dict[str, Any]) -> None:
    """B03's v1 spec with the printed fix applied to the model through its parameters: the
    heater and air-con gain and the base load lowered by the fix's constant."""
    fitted = json.loads((EXAMPLE / "models" / "ev_params.json").read_text(encoding="utf-8"))
    base_load_w = fitted["versions"]["1"]["params"]["base_load_w"]
    doc = yaml.safe_load(B03_V1.read_text(encoding="utf-8"))
    doc["reference"]["path"] = str(EXAMPLE / "data" / "i3" / "TripB03.parquet")
    doc["model"]["params"] = {
        "version": 1,
        "heater_aircon_gain": first["fix_coefficient"],
        "base_load_w": base_load_w + 1e3 * first["fix_constant"],
    }
    doc["model"]["inputs"] = ["Heating Power CAN [kW]", "AirCon Power [kW]"]
    target.write_text(yaml.safe_dump(doc, allow_unicode=True, sort_keys=False), encoding="utf-8")


def test_b03_fix_predicted_for_the_energy_is_what_the_fixed_model_scores(
    tmp_path: Path,
) -> None:
    diagnosed = tmp_path / "diagnosis.json"
    codes, printed = run_in_example(
        {"diagnose": ["diagnose", str(B03_V1), "--signal", POWER, "--json", str(diagnosed)]}
    )
    assert codes == {"diagnose": 0}
    found = json.loads(diagnosed.read_text(encoding="utf-8"))
    first = next(e for e in found["effects"] if e["relevant"])
    assert first["name"] == "heating_aircon_kw"
    # The energy is the model's running integral of the power, in kWh of kW over seconds.
    (above,) = found["above"]
    assert above["signal"] == ENERGY
    assert above["per_second"] == pytest.approx(1 / 3600, rel=1e-6)
    assert found["above_note"] is None
    (predicted,) = first["above"]
    energy = predicted["predicted"]
    # The diagnosis names the energy's predicted λ in the fix line.
    fix_line = next(line for line in printed["diagnose"].splitlines() if "fix:" in line)
    assert f"E_batt λ3 {above['lambdas']['mae']:.4f} → {energy['mae']:.4f}" in fix_line
    assert f"λ4 {above['lambdas']['rms']:.4f} → {energy['rms']:.4f}" in fix_line

    term = next(
        line.split("--try ", 1)[1].strip().strip("'")
        for line in printed["diagnose"].splitlines()
        if "try it:" in line
    )
    fixed = tmp_path / "b03-v1-fixed.hevval.yaml"
    _fixed_spec(fixed, first)
    tried, ran = tmp_path / "tried.json", tmp_path / "fixed.json"
    codes, printed = run_in_example(
        {
            "try": [
                "diagnose",
                str(B03_V1),
                "--signal",
                POWER,
                "--try",
                term,
                "--json",
                str(tried),
            ],
            "run": ["run", str(fixed), "--no-history", "--quiet", "--json", str(ran)],
        }
    )
    assert codes["try"] == 0
    # --try scores the energy again, before → after, with the term integrated.
    lines = printed["try"].splitlines()
    at = lines.index(
        "E_batt, the model's running integral of P_batt, with the term integrated the same way:"
    )
    assert lines[at + 1].startswith("  λ1 ")
    assert "λ3 " in lines[at + 1]
    assert lines[at + 2].startswith("  mean error ")
    assert "kWh" in lines[at + 2]
    again = json.loads(tried.read_text(encoding="utf-8"))["tried"]
    (energy_tried,) = again["above"]
    assert energy_tried["signal"] == ENERGY
    # Predicted as the spec scores it: --try's re-scored energy is the prediction.
    assert energy_tried["after"]["lambdas"][2] == pytest.approx(energy["mae"], abs=1e-4)
    assert energy_tried["after"]["lambdas"][3] == pytest.approx(energy["rms"], abs=1e-4)

    # Model v1 with the fix in its parameters, run through the whole pipeline, scores what the
    # diagnosis predicted, and better than before on both signals.
    result = json.loads(ran.read_text(encoding="utf-8"))
    signals = {s["path"]: s for s in result["signals"]}
    assert signals[ENERGY]["lambdas"]["mae"] == pytest.approx(energy["mae"], abs=0.01)
    assert signals[ENERGY]["lambdas"]["rms"] == pytest.approx(energy["rms"], abs=0.01)
    assert signals[POWER]["lambdas"]["mae"] == pytest.approx(first["predicted"]["mae"], abs=0.01)
    assert signals[POWER]["lambdas"]["rms"] == pytest.approx(first["predicted"]["rms"], abs=0.01)
    assert signals[ENERGY]["lambdas"]["mae"] > above["lambdas"]["mae"] + 0.02
    assert signals[ENERGY]["lambdas"]["rms"] > above["lambdas"]["rms"] + 0.02
    assert signals[POWER]["lambdas"]["mae"] > found["lambdas"]["mae"]
    assert signals[POWER]["lambdas"]["rms"] > found["lambdas"]["rms"]


def test_a_signal_whose_parent_is_no_integral_says_why(tmp_path: Path) -> None:
    """The current's parent, the power, is not its running integral: nothing above is
    predicted or re-scored, and both outputs say so in one line."""
    tried = tmp_path / "tried.json"
    current = f"{POWER}/I_batt"
    codes, printed = run_in_example(
        {
            "try": [
                "diagnose", str(B03_V1), "--signal", current,
                "--try", "0.5 * heating_aircon_kw", "--json", str(tried),
            ]
        }
    )  # fmt: skip
    assert codes == {"try": 0}
    why = "P_batt is not the running integral of I_batt in this model"
    document = json.loads(tried.read_text(encoding="utf-8"))
    assert document["above"] == []
    assert document["above_note"] == why
    assert document["tried"]["above"] == []
    assert document["tried"]["above_note"] == why
    assert f"(the signals above I_batt are not scored again: {why})" in printed["try"]
    if any(e["relevant"] for e in document["effects"]):
        assert f"the fixes are not predicted for the signals above I_batt: {why}" in printed["try"]


def test_html_report_shows_the_predicted_figures_above() -> None:
    from pytest_hevval.report import render_html
    from pytest_hevval.results.spec_result import SpecResult

    effect = {
        "name": "heating_aircon_kw",
        "kind": "declared",
        "share": 0.12,
        "coefficient": 1.12,
        "interval": [0.91, 1.32],
        "significant": True,
        "relevant": True,
        "members": [],
        "interchangeable": [],
        "stands_in_for": [],
        "fix": "add 1.12 × heating_aircon_kw and lower the model's constant by 1.47 kW",
        "then": "λ3 0.9809 → 0.9838, λ4 0.9721 → 0.9744; E_batt λ3 0.9213 → 0.9822, λ4 …",
    }
    signal = {
        "path": "E_batt/P_batt",
        **{"set": 1, "level": 2, "alpha": 1.0, "lag_s": 0.0, "peak_correlation": 1.0},
        **{"mae": 0.0, "rms": 0.0, "lambdas": [1.0]},
        "diagnosis": {"summary": "s", "effects": [effect], "above_note": None},
    }
    result = {"name": "b03", "spec": "b03.yaml", "phi": 1.0, "signals": [signal]}
    html = render_html(
        [SpecResult.from_dict(result)],
        title="t",
        generated_utc="2026-01-01 00:00:00 UTC",
    )
    assert "(then λ3 0.9809 → 0.9838, λ4 0.9721 → 0.9744; E_batt λ3 0.9213 → 0.9822" in html
    assert "not predicted for the signals above" not in html
    signal["diagnosis"]["above_note"] = "P_batt is not the running integral of I_batt"
    html = render_html(
        [SpecResult.from_dict(result)],
        title="t",
        generated_utc="2026-01-01 00:00:00 UTC",
    )
    assert (
        "The fixes are not predicted for the signals above: P_batt is not the running "
        "integral of I_batt." in html
    )


ENERGY_SPEC = """\
name: energy
reference: {path: ref.csv, time: t}
model: {path: sim.csv, time: t}
alignment: {max_lag_s: 3, nan: omit}
sets:
  - signal: E
    ref: "integrate(P)"
    sim: "integrate(P)"
    children:
      - {signal: P}
"""


def _energy_files(root: Path, *, gap: bool) -> Path:
    """A power the model lacks a heater in, and its energy, the running integral of it on both
    sides; with ``gap``, the measured power drops out for 20 s in the middle."""
    import pandas as pd

    rng = np.random.default_rng(8)
    t = np.arange(6000) * 0.1
    v = 15 + 10 * np.sin(t / 40)
    heater = 1.5 + np.clip(
        np.convolve(rng.normal(size=t.size), np.ones(400) / 400, "same") * 40, -1, 2
    )
    measured = 2 * v + heater + rng.normal(0, 0.5, t.size)
    if gap:
        measured[3000:3200] = np.nan
    pd.DataFrame({"t": t, "P": measured, "Heater [kW]": heater}).to_csv(
        root / "ref.csv", index=False
    )
    pd.DataFrame({"t": t, "P": 2 * v}).to_csv(root / "sim.csv", index=False)
    spec = root / "energy.hevval.yaml"
    spec.write_text(ENERGY_SPEC, encoding="utf-8")
    return spec


@pytest.mark.parametrize("gap", [False, True])
def test_try_scores_the_energy_again_unless_a_gap_breaks_the_running_sum(
    tmp_path: Path, gap: bool
) -> None:
    from pytest_hevval.cli import main

    spec = _energy_files(tmp_path, gap=gap)
    out = tmp_path / "t.json"
    assert (
        main(
            ["diagnose", str(spec), "--signal", "E/P", "--try", "`Heater [kW]`", "--json", str(out)]
        )
        == 0
    )
    document = json.loads(out.read_text(encoding="utf-8"))
    tried = document["tried"]
    if not gap:
        (energy,) = tried["above"]
        assert energy["signal"] == "E"
        assert tried["above_note"] is None
        # The model's power lacked the heater: the energy, with it integrated, is nearly exact.
        assert energy["after"]["lambdas"][2] > energy["before"]["lambdas"][2]
        assert abs(energy["after"]["mean_error"]) < 0.1 * abs(energy["before"]["mean_error"])
        first = next((e for e in document["effects"] if e["relevant"]), None)
        assert first is not None
        (above,) = first["above"]
        assert above["signal"] == "E"
    else:
        assert tried["above"] == []
        assert tried["above_note"] == (
            "a gap inside the scored samples interrupts the running integral of P, so E cannot "
            "be followed through it"
        )
        assert document["above"] == []

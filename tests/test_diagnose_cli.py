"""`hevval diagnose` and the one-line diagnosis in failure reports, on generated data."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest_plugins = ["pytester"]

SPEC = """\
name: ev
reference: {path: ref.csv, time: t}
model: {path: sim.csv, time: t}
alignment: {max_lag_s: 3}
thresholds: {mae: 0.97}
candidates:
  drag: "v ** 2"
sets:
  - signal: P
    children:
      - {signal: v}
"""


def make(root: Path, *, effect: bool, seed: int = 4) -> None:
    """P = 2·v + noise in the model; the measurement adds 30·grade when ``effect``.

    ``grade`` is a measured channel the spec never mentions, and ``cabin`` another one that
    has nothing to do with P.
    """
    rng = np.random.default_rng(seed)
    n = 6000
    t = np.arange(n) * 0.1
    smooth = np.ones(50) / 50
    v = 15 + 10 * np.sin(t / 40) + np.convolve(rng.normal(size=n), smooth, "same") * 3
    grade = np.convolve(rng.normal(size=n), np.ones(200) / 200, "same") * 8
    cabin = 20 + np.convolve(rng.normal(size=n), np.ones(300) / 300, "same") * 5
    noise = rng.normal(0, 0.3, n)
    measured = 2 * v + (30 * grade if effect else 0) + noise
    pd.DataFrame({"t": t, "P": measured, "v": v, "grade": grade, "cabin": cabin}).to_csv(
        root / "ref.csv", index=False
    )
    pd.DataFrame({"t": t, "P": 2 * v, "v": v}).to_csv(root / "sim.csv", index=False)
    (root / "ev.hevval.yaml").write_text(SPEC)


def run_diagnose(pytester: pytest.Pytester, *args: str) -> dict:
    result = pytester.run(
        sys.executable, "-m", "pytest_hevval", "diagnose", "ev.hevval.yaml", *args,
        "--json", "d.json",
    )  # fmt: skip
    assert result.ret == 0, result.stderr.str()
    return json.loads((pytester.path / "d.json").read_text())


def test_undeclared_channel_is_found(pytester: pytest.Pytester) -> None:
    make(pytester.path, effect=True)
    found = run_diagnose(pytester, "--signal", "P")
    assert {"signal", "origin", "lag_s", "gain", "offset", "candidates", "remaining"} <= set(found)
    assert found["signal"] == "P"
    assert found["origin"] == {"path": "P", "level": 1}
    best = found["candidates"][0]
    assert {"name", "kind", "explained_fraction", "coefficient", "significant"} <= set(best)
    assert (best["name"], best["kind"], best["significant"]) == ("grade", "channel", True)
    assert best["interval"][0] <= 30 <= best["interval"][1]
    assert best["explained_fraction"] > 0.8
    by_name = {c["name"]: c for c in found["candidates"]}
    assert not by_name["cabin"]["significant"]


def test_no_effect_reports_nothing_significant(pytester: pytest.Pytester) -> None:
    make(pytester.path, effect=False)
    found = run_diagnose(pytester, "--signal", "P")
    assert not any(c["significant"] for c in found["candidates"])
    assert "no significant effect" in found["summary"]


def test_failure_report_carries_the_diagnosis_line(pytester: pytest.Pytester) -> None:
    make(pytester.path, effect=True)
    result = pytester.runpytest("--hevval", "--hevval-no-history")
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(
        [
            "P missed its thresholds (ev.hevval.yaml:9)",
            "*diagnosis: grade explains *",
            "  next: hevval diagnose ev.hevval.yaml --signal P *",
        ]
    )
    quiet = pytester.runpytest("--hevval", "--hevval-no-history", "--hevval-diagnose=off")
    assert "diagnosis:" not in quiet.stdout.str()


def test_unknown_signal_is_a_clear_error(pytester: pytest.Pytester) -> None:
    make(pytester.path, effect=True)
    result = pytester.run(
        sys.executable, "-m", "pytest_hevval", "diagnose", "ev.hevval.yaml", "--signal", "Q"
    )
    assert result.ret == 2
    assert "no signal 'Q' in this spec" in result.stderr.str()


ENERGY_SPEC = """\
name: energy
reference: {path: ref.csv, time: t}
model: {path: sim.csv, time: t}
alignment: {max_lag_s: 3}
thresholds: {mae: 0.99}
sets:
  - signal: E
    ref: "integrate(P)"
    sim: "integrate(P)"
    children:
      - {signal: P, thresholds: {mae: 0.8}}
"""


def make_energy(root: Path, seed: int = 8) -> None:
    """The measured power holds a heater the model lacks, logged twice (in kW and as a current
    in A): the power passes its gate and the error appears where it adds up, in the energy."""
    rng = np.random.default_rng(seed)
    n = 6000
    t = np.arange(n) * 0.1
    v = 15 + 10 * np.sin(t / 40) + np.convolve(rng.normal(size=n), np.ones(50) / 50, "same") * 3
    heater = 1.5 + np.clip(np.convolve(rng.normal(size=n), np.ones(400) / 400, "same") * 40, -1, 2)
    current = heater * 1000 / 380 + rng.normal(0, 0.05, n)
    measured = 2 * v + heater + rng.normal(0, 0.5, n)
    pd.DataFrame(
        {"t": t, "P": measured, "Heater [kW]": heater, "Heater Current [A]": current}
    ).to_csv(root / "ref.csv", index=False)
    pd.DataFrame({"t": t, "P": 2 * v}).to_csv(root / "sim.csv", index=False)
    (root / "energy.hevval.yaml").write_text(ENERGY_SPEC)


@pytest.mark.parametrize("workers", [[], ["-n", "2"]])
def test_a_failing_running_sum_points_at_the_level_that_names_the_load(
    pytester: pytest.Pytester, workers: list[str]
) -> None:
    """The energy fails, its power passes: the diagnosis looks one level down, where the
    missing load shows at each instant, names it once for its two channels, and the `next:`
    hint sends the user there."""
    make_energy(pytester.path)
    result = pytester.runpytest("--hevval", "--hevval-no-history", *workers)
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(
        [
            "E missed its thresholds (energy.hevval.yaml:7)",
            "*diagnosis: (in E/P, below E) Heater * (one effect with Heater *) explains *",
            "  next: hevval diagnose energy.hevval.yaml --signal E/P *",
        ]
    )


def make_base_load(root: Path, seed: int = 8) -> None:
    """The model's constant base load (1 kW) already covers part of a heater's mean (1.5 kW)
    that it otherwise lacks: the fix must add the heater and lower the constant."""
    make_energy(root, seed)
    sim = pd.read_csv(root / "sim.csv")
    sim["P"] = sim["P"] + 1.0
    sim.to_csv(root / "sim.csv", index=False)


def test_the_printed_fix_tried_through_the_spec_scores_as_predicted(
    pytester: pytest.Pytester,
) -> None:
    make_base_load(pytester.path)
    result = pytester.run(
        sys.executable, "-m", "pytest_hevval", "diagnose", "energy.hevval.yaml",
        "--signal", "E/P", "--json", "d.json",
    )  # fmt: skip
    assert result.ret == 0, result.stderr.str()
    found = json.loads((pytester.path / "d.json").read_text())
    first = next(e for e in found["effects"] if e["relevant"])
    assert "Heater" in first["name"]
    # The heater's mean (1.5 kW) less what the base load already covers (1 kW) is what the
    # model lacks on average: the fix lowers the constant by about the 1 kW it double counts.
    assert 0.9 < first["fix_coefficient"] < 1.1
    assert -1.3 < first["fix_constant"] < -0.7
    assert "lower the model's constant by" in first["fix"]
    try_line = next(line for line in result.stdout.lines if "try it:" in line)
    term = try_line.split("--try ", 1)[1].strip("'")
    tried = pytester.run(
        sys.executable, "-m", "pytest_hevval", "diagnose", "energy.hevval.yaml",
        "--signal", "E/P", "--try", term, "--json", "t.json",
    )  # fmt: skip
    assert tried.ret == 0, tried.stderr.str()
    assert "added to the model's output, scored through the spec:" in tried.stdout.str()
    after = json.loads((pytester.path / "t.json").read_text())["tried"]["after"]
    # λ3 and λ4 in paper order; what the diagnosis predicted is what the spec scores.
    assert after["lambdas"][2] == pytest.approx(first["predicted"]["mae"], abs=0.01)
    assert after["lambdas"][3] == pytest.approx(first["predicted"]["rms"], abs=0.01)
    assert abs(after["mean_error"]) < 0.01


def test_a_bad_try_term_is_a_clear_error(pytester: pytest.Pytester) -> None:
    make_energy(pytester.path)
    result = pytester.run(
        sys.executable, "-m", "pytest_hevval", "diagnose", "energy.hevval.yaml",
        "--signal", "E/P", "--try", "2 * `Heater [MW]`",
    )  # fmt: skip
    assert result.ret == 2
    err = result.stderr.str()
    assert "--try '2 * `Heater [MW]`'" in err
    assert "Heater [MW]" in err
    assert "Traceback" not in err

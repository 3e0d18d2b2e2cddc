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

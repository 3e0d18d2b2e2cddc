"""Reports: figure data, the view-model, HTML / JSON / Markdown, CI annotations, files."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import os
import re
import stat
import subprocess
import sys
import time
from html import escape
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval.core.characteristics import signal_characteristics
from pytest_hevval.errors import DegenerateSignalError, HevvalError, MissingExtraError
from pytest_hevval.flags import COMMAND
from pytest_hevval.report import (
    ReportOptionError,
    figure_data,
    github_annotations,
    model,
    parse_formats,
    render_html,
    render_json,
    render_markdown,
    svg,
    write_reports,
)
from pytest_hevval.report.panels import SignalPanels
from pytest_hevval.results.recorded import RecordedPoint
from pytest_hevval.results.spec_result import SignalResult, SpecResult

STAMP = "2026-01-01 00:00:00 UTC"


# --------------------------------------------------------------------------- helpers


def _pair(n: int, seed: int = 0, lag: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n)
    ref = 40.0 * np.sin(t / 97.0) + 5.0 * np.sin(t / 7.0) + rng.normal(0.0, 1.0, n)
    sim = np.roll(ref, lag) * 0.97 + rng.normal(0.0, 1.5, n)
    return ref, sim


def _signal(
    path: str,
    *,
    lambdas: list[float] | None = None,
    thresholds: dict[str, float] | None = None,
    figures: dict[str, Any] | None = None,
    origin: bool = False,
    origins: list[str] | None = None,
    line: int = 10,
    level: int | None = None,
    position: int = 1,
) -> dict[str, Any]:
    lambdas = lambdas or [0.99, 0.9, 0.95, 0.94, 0.99, 0.95, 1.0]
    thresholds = thresholds or {}
    failures = [
        {"characteristic": name, "value": lambdas[i], "threshold": thresholds[name]}
        for i, name in enumerate(model.CHARACTERISTICS)
        if name in thresholds and lambdas[i] < thresholds[name]
    ]
    return {
        "path": path,
        "name": path.rsplit("/", 1)[-1],
        "set": 1,
        "level": level if level is not None else path.count("/") + 1,
        "position": position,
        "alpha": 1.0,
        "line": line,
        "unit": "kW",
        "lambdas": lambdas,
        "lag_s": -0.2,
        "peak_correlation": 0.99,
        "mae": 1.2,
        "rms": 2.0,
        "delta_e": 0.8,
        "error_std": 1.9,
        "mean_error": 0.1,
        "reference_range": 80.0,
        "n_samples": 1000,
        "thresholds": thresholds,
        "failures": failures,
        "passed": not failures,
        "origin": origin,
        "origins": origins if origins is not None else ([path] if failures else []),
        "figures": figures,
        "diagnosis": None,
        "history": None,
    }


def _spec(signals: list[dict[str, Any]], *, phi: float = 0.94, min_phi: float = 0.9) -> dict:
    return {
        "schema_version": 1,
        "name": "i3 trip A01",
        "spec": "specs/trip_a01.hevval.yaml",
        "spec_hash": "abc123",
        "phi": phi,
        "min_phi": min_phi,
        "passed": phi >= min_phi and all(s["passed"] for s in signals),
        "alignment": {
            "rate_hz": 10.0,
            "start_s": 0.0,
            "stop_s": 99.9,
            "n_samples": 1000,
            "offset_s": 0.0,
            "coverage": 1.0,
        },
        "signals": signals,
    }


@pytest.fixture(scope="module")
def figures() -> dict[str, Any]:
    ref, sim = _pair(5000, lag=3)
    return figure_data(ref, sim, dt=0.1, start_s=0.0, max_lag=100)


@pytest.fixture
def results(figures: dict[str, Any]) -> list[dict[str, Any]]:
    return _results(figures)


@pytest.fixture(scope="module")
def page(figures: dict[str, Any]) -> str:
    """The HTML report of :func:`_results`, rendered once for the read-only checks."""
    return render_html(_typed(_results(figures)), title="Validation", generated_utc=STAMP)


def _typed(specs: list[dict[str, Any]]) -> list[SpecResult]:
    """The results as the reports take them."""
    return [SpecResult.from_dict(spec) for spec in specs]


def _typed_one(spec: dict[str, Any]) -> SpecResult:
    return SpecResult.from_dict(spec)


def _results(figures: dict[str, Any]) -> list[dict[str, Any]]:
    """A spec whose P_batt fails on MAE (origin) and whose parent E_batt inherits it."""
    parent = _signal(
        "E_batt",
        lambdas=[0.99, 0.9, 0.95, 0.94, 0.99, 0.95, 0.82],
        thresholds={"emergent": 0.85},
        origins=["E_batt/P_batt"],
        line=8,
        figures=figures,
    )
    child = _signal(
        "E_batt/P_batt",
        lambdas=[0.99, 0.9, 0.85, 0.94, 0.99, 0.95, 1.0],
        thresholds={"mae": 0.9, "lag_correlation": 0.95},
        origin=True,
        line=14,
        figures=figures,
    )
    sibling = _signal(
        "E_batt/U_batt", thresholds={"mae": 0.9}, line=20, position=2, figures=figures
    )
    good = _spec([_signal("v", thresholds={"mae": 0.9}, figures=figures)], phi=0.97)
    good["name"] = "i3 trip A02"
    good["spec"] = "specs/trip_a02.hevval.yaml"
    return [_spec([sibling, parent, child], phi=0.8123), good]


# --------------------------------------------------------------------------- figure data


@settings(max_examples=25, deadline=None)
@given(
    n=st.integers(min_value=3, max_value=5000),
    points=st.integers(min_value=1, max_value=700),
    seed=st.integers(min_value=0, max_value=2**31),
)
def test_envelope_holds_the_true_extremes_of_every_bucket(n: int, points: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    ref = rng.normal(0.0, 10.0, n).cumsum()
    sim = ref + rng.standard_cauchy(n)
    data = figure_data(ref, sim, dt=0.01, start_s=3.0, max_lag=min(50, n - 1), points=points)
    ov = data["overlay"]
    buckets = min(points, n)
    assert len(ov["time"]) == buckets
    assert sum(ov["count"]) == n
    edges = np.cumsum([0, *ov["count"]])
    residual = ref - sim
    for series, values in (("ref", ref), ("sim", sim), ("res", residual)):
        low = np.asarray(ov[f"{series}_min"])
        high = np.asarray(ov[f"{series}_max"])
        # Six significant digits relative to the largest magnitude of the series.
        tol = 1e-5 * max(float(np.max(np.abs(values))), 1e-300)
        for b in range(buckets):
            chunk = values[edges[b] : edges[b + 1]]
            assert low[b] == pytest.approx(chunk.min(), abs=tol)
            assert high[b] == pytest.approx(chunk.max(), abs=tol)
    assert data["n_samples"] == n
    assert ov["time"][0] >= 3.0
    assert ov["time"][-1] <= 3.0 + (n - 1) * 0.01 + 1e-9


@settings(max_examples=25, deadline=None)
@given(
    n=st.integers(min_value=3, max_value=4000),
    points=st.integers(min_value=1, max_value=500),
    seed=st.integers(min_value=0, max_value=2**31),
)
def test_derivative_match_per_bucket_averages_to_lambda2(n: int, points: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    ref = rng.normal(0.0, 1.0, n).cumsum()
    # Quantised samples give flat steps (derivative 0), the case that is easy to get wrong.
    sim = np.round(ref + rng.normal(0.0, 0.7, n))
    data = figure_data(ref, sim, dt=0.5, start_s=0.0, max_lag=1)
    match = np.asarray(data["derivative"]["match"])
    counts = np.asarray(data["overlay"]["count"])
    weighted = float((match * counts).sum() / counts.sum())
    expected = signal_characteristics(ref, sim, dt=0.5).derivative_match
    assert data["derivative"]["fraction"] == pytest.approx(expected, abs=1e-12)
    assert weighted == pytest.approx(expected, abs=1e-4)  # match is rounded to 4 decimals
    assert ((match >= 0.0) & (match <= 1.0)).all()


def test_histogram_counts_every_sample_and_its_cdf_ends_at_one() -> None:
    ref, sim = _pair(12345)
    data = figure_data(ref, sim, dt=0.01, start_s=0.0, max_lag=200, bins=50)
    hist = data["histogram"]
    assert sum(hist["counts"]) == 12345
    assert len(hist["edges"]) == 51
    assert len(hist["cdf"]) == 50
    assert hist["cdf"][-1] == pytest.approx(1.0)
    assert all(a <= b for a, b in zip(hist["cdf"], hist["cdf"][1:], strict=False))
    residual = ref - sim
    assert hist["edges"][0] == pytest.approx(residual.min(), rel=1e-5)
    assert hist["edges"][-1] == pytest.approx(residual.max(), rel=1e-5)
    assert hist["std"] == pytest.approx(residual.std(ddof=1), rel=1e-5)


def test_correlation_peak_is_at_the_models_lag_with_the_papers_sign() -> None:
    # The simulation lags the measurement by 4 samples: the peak must be at −4·dt (Fig. 5).
    ref, sim = _pair(4000, lag=4)
    data = figure_data(ref, sim, dt=0.05, start_s=0.0, max_lag=40)
    corr = data["correlation"]
    assert corr["peak_lag_s"] == pytest.approx(-0.2)
    assert corr["peak"] == max(corr["value"])
    assert corr["zero_lag"] < corr["peak"]
    assert corr["max_lag_s"] == pytest.approx(2.0)
    assert len(corr["lag_s"]) == len(corr["value"]) == 81


def test_figure_data_is_json_safe_and_small() -> None:
    ref, sim = _pair(100_000)
    data = figure_data(ref, sim, dt=0.01, start_s=0.0, max_lag=1000)
    text = json.dumps(data, allow_nan=False)
    assert len(data["overlay"]["time"]) == 2000
    assert len(text) < 250_000
    assert json.loads(text) == data


@pytest.mark.parametrize(
    ("reference", "simulated", "dt", "message"),
    [
        ([1.0, 2.0, 3.0], [1.0, 2.0], 0.1, "equal length"),
        ([1.0, 2.0], [1.0, 2.0], 0.1, "at least 3 samples"),
        ([1.0, math.nan, 3.0], [1.0, 2.0, 3.0], 0.1, "finite"),
        ([1.0, 2.0, 3.0], [1.0, 2.0, 3.0], 0.0, "dt must be"),
    ],
)
def test_figure_data_rejects_unusable_input(
    reference: list[float], simulated: list[float], dt: float, message: str
) -> None:
    with pytest.raises(DegenerateSignalError, match=message):
        figure_data(reference, simulated, dt=dt, start_s=0.0, max_lag=1)


@pytest.mark.slow
def test_figure_data_of_one_hour_at_100_hz_is_fast() -> None:
    ref, sim = _pair(360_000, lag=20)
    figure_data(ref[:1000], sim[:1000], dt=0.01, start_s=0.0, max_lag=10)  # warm imports
    timings = []
    for max_lag in (36_000, 500):
        for _ in range(3):
            start = time.perf_counter()
            figure_data(ref, sim, dt=0.01, start_s=0.0, max_lag=max_lag)
            timings.append(time.perf_counter() - start)
    # The target is well under 0.1 s; the bound leaves room for a loaded CI machine while
    # still catching anything that is not linear-time.
    assert min(timings) < 0.25


# --------------------------------------------------------------------------- view-model


def test_cells_colour_every_lambda_against_its_threshold() -> None:
    signal = _signal(
        "a", lambdas=[0.99, 0.5, 0.85, 0.9, 1.0, 0.9, 1.0], thresholds={"mae": 0.9, "rms": 0.9}
    )
    typed = SignalResult.from_dict(signal)
    statuses = [c.status for c in model.cells(typed)]
    assert statuses == ["ungated", "ungated", "fail", "pass", "ungated", "ungated", "ungated"]
    assert model.margin(typed) == pytest.approx(-0.05)


def test_tree_rows_put_children_under_their_parent_in_position_order(
    results: list[dict[str, Any]],
) -> None:
    rows = model.tree_rows(_typed(results)[0])
    assert [(s.path, depth) for s, depth in rows] == [
        ("E_batt", 0),
        ("E_batt/P_batt", 1),
        ("E_batt/U_batt", 1),
    ]


def test_worst_rows_put_failing_signals_first(results: list[dict[str, Any]]) -> None:
    rows = model.worst_rows(_typed(results), limit=3)
    assert [r.signal.path for r in rows[:2]] == ["E_batt/P_batt", "E_batt"]
    assert rows[0].worst is not None
    assert rows[0].worst.characteristic == "mae"


def test_glyph_points_weigh_each_lambda_by_alpha_times_beta(
    results: list[dict[str, Any]],
) -> None:
    spec = copy.deepcopy(results[0])
    spec["weights"] = [1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 2.0]
    spec["signals"][0]["alpha"] = 0.7
    points = [p for p in model.glyph_points(_typed_one(spec)) if p.signal == "E_batt/U_batt"]
    assert [p.weight for p in points] == pytest.approx([0.7, 0.35, 0.7, 0.7, 0.7, 0.7, 1.4])
    assert {p.level for p in points} == {2}


def test_nice_ticks_are_round_and_cover_the_range() -> None:
    assert svg.nice_ticks(0.0, 1007.9, 5) == [0.0, 250.0, 500.0, 750.0, 1000.0]
    assert svg.nice_ticks(-0.37, 0.41, 4) == pytest.approx([-0.2, 0.0, 0.2, 0.4])
    assert svg.nice_ticks(3.0, 17.0, 7) == [4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0]
    assert svg.nice_ticks(2.0, 2.0) == [2.0]


# --------------------------------------------------------------------------- markdown / json


def test_markdown_summarises_each_spec_and_its_failing_signals(
    results: list[dict[str, Any]],
) -> None:
    text = render_markdown(_typed(results))
    assert text.startswith(
        "### ❌ hevval: 2 spec files, 1 pass; 6 items, 3 fail: 2 of 4 signals, 1 of 2 Φ\n"
    )
    assert "| ❌ | i3 trip A01 | 0.8123 | 0.9000 | 2 / 3 |" in text
    assert "| ✅ | i3 trip A02 | 0.9700 | 0.9000 | 0 / 1 |" in text
    assert "**❌ i3 trip A01** — Φ 0.8123 < min Φ 0.9000" in text
    assert "| `E_batt/P_batt` (line 14) | λ3 MAE 0.850 &lt; 0.900 | here |" in text
    assert "| `E_batt` (line 8) | λ7 emergent 0.820 &lt; 0.850 | E_batt/P_batt |" in text
    assert "U_batt" not in text  # passing signals stay out of a short summary
    assert "i3 trip A02**" not in text


def test_markdown_escapes_table_breaking_names(results: list[dict[str, Any]]) -> None:
    results[0]["signals"][2]["path"] = "a|b<c>"
    text = render_markdown(_typed(results))
    assert "`a\\|b&lt;c&gt;`" in text
    assert "<c>" not in text


def test_json_is_sorted_stable_and_complete(results: list[dict[str, Any]]) -> None:
    results[0]["signals"][0]["mae"] = math.nan
    text = render_json(_typed(results))
    assert text == render_json(_typed(copy.deepcopy(results)))
    payload = json.loads(text)
    compact = json.dumps(payload, sort_keys=True, ensure_ascii=False, separators=(",", ":"))
    assert text == compact + "\n"
    assert payload["report_schema_version"] == 1
    assert payload["summary"] == {
        "signals": 4,
        "signals_failed": 2,
        "specs": 2,
        "specs_failed": 1,
        "outcome": "2 spec files, 1 pass; 6 items, 3 fail: 2 of 4 signals, 1 of 2 Φ",
        "passed": False,
        "regressions": 0,
    }
    assert payload["specs"][0]["signals"][0]["mae"] is None
    assert payload["specs"][0]["signals"][1]["figures"] == results[0]["signals"][1]["figures"]
    assert [w["path"] for w in payload["worst"][:2]] == ["E_batt/P_batt", "E_batt"]


def test_json_turns_numpy_values_into_plain_numbers(results: list[dict[str, Any]]) -> None:
    typed = _typed(results)
    signal = dataclasses.replace(
        typed[0].signals[0],
        lambdas={"mae": np.float64(np.inf), "rms": np.float32(0.5)},  # type: ignore[dict-item]
        figures={"steps": np.array([1.0, np.nan, 2])},
    )
    typed[0] = dataclasses.replace(
        typed[0],
        phi=np.float32(0.5),  # type: ignore[arg-type]
        signals=[signal, *typed[0].signals[1:]],
    )
    payload = json.loads(render_json(typed))
    assert payload["specs"][0]["phi"] == 0.5
    assert payload["specs"][0]["signals"][0]["lambdas"] == {"mae": None, "rms": 0.5}
    assert payload["specs"][0]["signals"][0]["figures"] == {"steps": [1.0, None, 2.0]}


# --------------------------------------------------------------------------- annotations


def test_annotations_point_at_the_failing_signals_spec_line(
    results: list[dict[str, Any]], tmp_path: Path
) -> None:
    lines = github_annotations(_typed(results), tmp_path)
    assert lines == [
        "::error file=specs/trip_a01.hevval.yaml,title=hevval::i3 trip A01: Φ 0.8123 is below "
        "min Φ 0.9000",
        "::error file=specs/trip_a01.hevval.yaml,line=14,title=hevval::i3 trip A01: "
        "E_batt/P_batt: λ3 MAE 0.850 < 0.900 (the error appears in this signal)",
        "::error file=specs/trip_a01.hevval.yaml,line=8,title=hevval::i3 trip A01: E_batt: "
        "λ7 emergent 0.820 < 0.850 (the error appears in E_batt/P_batt)",
    ]


def test_annotations_make_paths_relative_and_escape_commands(
    results: list[dict[str, Any]], tmp_path: Path
) -> None:
    results[0]["spec"] = str(tmp_path / "specs" / "a,b.hevval.yaml")
    results[0]["name"] = "two\nlines 100%"
    first = github_annotations(_typed(results), tmp_path)[0]
    assert first.startswith("::error file=specs/a%2Cb.hevval.yaml,title=hevval::two%0Alines 100%25")
    assert "\n" not in first


# --------------------------------------------------------------------------- html


def test_html_is_one_self_contained_file(page: str) -> None:
    html = page
    assert html.startswith("<!DOCTYPE html>")
    assert "http://" not in html
    assert "https://" not in html
    assert "<script" not in html.lower()
    assert "<link" not in html.lower()
    assert not re.search(r"url\((?!#)", html)  # CSS may only reference in-page ids
    # Every plot is inline SVG: not even an embedded bitmap.
    assert not re.search(r"\ssrc=", html)
    hrefs = re.findall(r'\shref="([^"]*)"', html)
    assert hrefs
    assert all(h.startswith("#") for h in hrefs)
    ids = set(re.findall(r'\sid="([^"]*)"', html))
    assert {h[1:] for h in hrefs} <= ids  # every in-page link has a target


def test_html_shows_phi_tree_glyph_plot_and_every_signal_plot(page: str) -> None:
    html = page
    assert "Φ = 0.8123" in html
    assert "Φ = 0.9700" in html
    assert 'class="phi fail"' in html
    assert 'class="phi pass"' in html
    assert html.count('<svg class="hv-glyph"') == 2  # one glyph plot per spec
    assert html.count('<svg class="hv-plot"') == 4  # one plot per signal
    assert html.count('class="badge origin"') >= 2
    # The failing MAE cell is red, the emergent one too; ungated ones are grey.
    assert re.search(r'<td class="lam fail"[^>]*>0\.8500', html)
    assert re.search(r'<td class="lam fail"[^>]*>0\.8200', html)
    assert 'class="lam ungated"' in html
    assert STAMP in html


def test_html_puts_failing_signals_first(page: str) -> None:
    html = page
    details = re.findall(r'<details class="signal([^"]*)" id="([^"]*)"', html)
    first_spec = [anchor for _, anchor in details if anchor.startswith("spec0-")]
    assert [a.split("-", 2)[2] for a in first_spec] == ["E_batt-P_batt", "E_batt", "E_batt-U_batt"]


def test_html_escapes_names_and_text(results: list[dict[str, Any]]) -> None:
    results[0]["name"] = "<script>alert(1)</script>"
    results[0]["signals"][0]["unit"] = '"><img src=x>'
    results[0]["signals"][0]["diagnosis"] = {
        "summary": "<b>bold</b>",
        "candidates": [
            {
                "name": "<i>",
                "kind": "lag",
                "explained_fraction": 0.5,
                "coefficient": 1.0,
                "significant": True,
            }
        ],
    }
    html = render_html(_typed(results), title="<T>", generated_utc=STAMP)
    assert "<script>alert" not in html
    assert "<img src=x>" not in html
    assert "<b>bold</b>" not in html
    assert "&lt;b&gt;bold&lt;/b&gt;" in html
    assert "<title>&lt;T&gt;</title>" in html


def test_html_shows_diagnosis_and_history_when_present(
    results: list[dict[str, Any]],
) -> None:
    signal = results[0]["signals"][2]
    signal["diagnosis"] = {
        "summary": "lag explains most of the residual",
        "candidates": [
            {
                "name": "lag(0.2 s)",
                "kind": "lag",
                "explained_fraction": 0.62,
                "coefficient": 0.2,
                "significant": True,
            },
        ],
    }
    # Points as an old history index holds them: λ listed in paper order.
    history = [
        RecordedPoint.from_json("v1", 0.90, [0.9] * 7),
        RecordedPoint.from_json("v2", 0.81, [0.8] * 7),
    ]
    signal["diagnosis"]["effects"] = [
        {
            "name": "heater_kw",
            "kind": "declared",
            "share": 0.111,
            "coefficient": 0.987,
            "interval": [0.694, 1.28],
            "significant": True,
            "relevant": True,
            "members": ["Heater Current [A]", "Heating Power LIN [W]"],
            "interchangeable": ["Battery Temperature [°C]"],
            "stands_in_for": [],
            "fix": "add 0.987 × heater_kw and lower the model's constant by 1.2 kW",
        },
        {
            "name": "Battery Temperature [°C]",
            "kind": "channel",
            "share": 0.07,
            "coefficient": -1.45,
            "interval": [-2.12, -0.785],
            "significant": True,
            "relevant": False,
            "members": [],
            "interchangeable": ["heater_kw"],
            "stands_in_for": ["heater_kw"],
        },
        {
            "name": "noise",
            "kind": "channel",
            "share": 0.001,
            "coefficient": 0.1,
            "interval": [-1.0, 1.0],
            "significant": False,
            "relevant": False,
            "members": [],
            "interchangeable": [],
            "stands_in_for": [],
        },
    ]
    panels = SignalPanels(
        trends={(results[0]["spec"], signal["path"]): history}, model_version="v3"
    )
    html = render_html(_typed(results), title="Validation", generated_utc=STAMP, panels=panels)
    assert "lag explains most of the residual" in html
    assert "62.0 %" in html
    # Effects: each with its one share and coefficient, its members and its reading.
    assert "11.1 %" in html
    assert "also measured by Heater Current [A], Heating Power LIN [W]" in html
    assert ">finding<" in html
    # A finding shows the fix as the user applies it, as the terminal does.
    assert "fix: add 0.987 × heater_kw and lower the model&#39;s constant by 1.2 kW" in html
    assert "could stand in for heater_kw" in html
    assert ">noise<" not in html
    assert html.count('<svg class="hv-plot hv-small"') == 1
    assert ">v2</text>" in html
    assert ">v3</text>" in html


def test_html_survives_missing_optional_fields() -> None:
    signal = {"path": "x", "set": 1, "level": 1, "alpha": 1.0, "lambdas": [1.0]}
    signal.update(lag_s=0.0, peak_correlation=1.0, mae=0.0, rms=0.0)
    bare = {"name": "bare", "spec": "bare.yaml", "phi": math.nan, "signals": [signal]}
    html = render_html(_typed([bare]), title="t", generated_utc=STAMP)
    assert "No figure data for this signal." in html
    assert "Φ = —" in html


@pytest.mark.slow
def test_html_of_20_signals_one_hour_at_100_hz_stays_under_800_kb() -> None:
    n = 360_000
    signals = []
    for k in range(20):
        ref, sim = _pair(n, seed=k, lag=k % 5)
        chars = signal_characteristics(ref, sim, dt=0.01, max_lag_s=5.0)
        signal = _signal(f"sys/s{k:02d}", lambdas=[*chars.lambdas, 1.0], thresholds={"mae": 0.97})
        signal["figures"] = figure_data(ref, sim, dt=0.01, start_s=0.0, max_lag=500)
        signals.append(signal)
    html = render_html(_typed([_spec(signals)]), title="one hour", generated_utc=STAMP)
    size = len(html.encode("utf-8"))
    assert html.count('<svg class="hv-plot"') == 20
    # One point per pixel column at whole pixels: noisy traces cost about 30 KB a plot.
    assert 500_000 < size < 800_000


# --------------------------------------------------------------------------- svg plots


def _vertices(d: str) -> list[tuple[int, int]]:
    """The vertices of path data written as ``M x y l dx dy …`` in whole units."""
    found = re.fullmatch(r"M(-?\d+) (-?\d+)(?:l([-\d ]+))?Z?", d)
    assert found, d
    x, y = int(found[1]), int(found[2])
    points = [(x, y)]
    steps = [int(v) for v in re.findall(r"-?\d+", found[3] or "")]
    for dx, dy in zip(steps[::2], steps[1::2], strict=True):
        x, y = x + dx, y + dy
        points.append((x, y))
    return points


def _band(plot: str, css: str) -> str:
    """Path data of the one element of class ``css`` in ``plot``, drawn inline or shared."""
    found = re.findall(
        rf'<path class="{css}" d="([^"]*)"|<g class="{css}"><path id="[^"]+" d="([^"]*)"', plot
    )
    assert len(found) == 1, found
    return found[0][0] or found[0][1]


@settings(max_examples=60, deadline=None)
@given(
    steps=st.lists(
        st.tuples(st.sampled_from([-1, 0, 1, 2]), st.sampled_from([-2, 0, 0, 1, 3])),
        min_size=0,
        max_size=80,
    ),
    start=st.tuples(st.integers(-50, 900), st.integers(-50, 500)),
    jitter=st.floats(min_value=-0.45, max_value=0.45),
)
def test_path_data_passes_through_every_point_in_order(
    steps: list[tuple[int, int]], start: tuple[int, int], jitter: float
) -> None:
    exact = np.cumsum(np.array([start, *steps], dtype=np.int64), axis=0)
    drawn = _vertices(svg._path(exact[:, 0] + jitter, exact[:, 1] - jitter))
    given_points = [tuple(p) for p in exact.tolist()]
    # Repeats of a point draw nothing; every other point must be a vertex or lie on the segment
    # between two, in order and in the segment's direction.
    wanted = [p for k, p in enumerate(given_points) if k == 0 or p != given_points[k - 1]]
    assert drawn[0] == wanted[0]
    assert set(drawn) <= set(wanted)
    vertex, progress = 0, 0
    for point in wanted[1:]:
        if vertex + 1 < len(drawn) and point == drawn[vertex + 1]:
            vertex, progress = vertex + 1, 0
            continue
        assert vertex + 1 < len(drawn), point
        (ax, ay), (bx, by) = drawn[vertex], drawn[vertex + 1]
        ux, uy = bx - ax, by - ay
        px, py = point[0] - ax, point[1] - ay
        along = ux * px + uy * py
        assert ux * py - uy * px == 0, (point, drawn[vertex], drawn[vertex + 1])
        assert progress < along < ux * ux + uy * uy
        progress = along
    assert vertex == len(drawn) - 1


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(min_value=1, max_value=3000),
    columns=st.integers(min_value=1, max_value=900),
    seed=st.integers(min_value=0, max_value=2**31),
)
def test_column_envelope_holds_the_extremes_of_every_pixel_column(
    n: int, columns: int, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    column = np.sort(rng.integers(0, columns, n))
    times = 3.0 + (column + rng.uniform(0.1, 0.9, n)) * (7.0 / columns)
    lows = rng.standard_cauchy(n)
    highs = lows + rng.exponential(1.0, n)
    lows[rng.random(n) < 0.1] = np.nan  # a missing value leaves the rest of its column
    centres, low, high = svg.column_envelope(times, lows, highs, 3.0, 10.0, columns)
    assert centres.tolist() == [c + 0.5 for c in sorted(set(column.tolist()))]
    for c, lo, hi in zip(centres, low, high, strict=True):
        inside = column == int(c)
        if np.isnan(lows[inside]).all():
            assert np.isnan(lo)
        else:
            assert lo == np.nanmin(lows[inside])
        assert hi == highs[inside].max()


def test_a_spike_one_sample_wide_keeps_its_full_height_and_place() -> None:
    n = 100_000
    ref = np.zeros(n)
    ref[31_337], ref[77_777] = 100.0, -100.0
    data = figure_data(ref, np.zeros(n), dt=0.01, start_s=0.0, max_lag=10)
    signal = SignalResult.from_dict({**_signal("x"), "figures": data})
    plot = svg.signal_svg(signal, "s")
    assert plot is not None
    for css in ("hv-ref", "hv-res"):
        points = _vertices(_band(plot, css))
        xs = [x for x, _ in points]
        levels = sorted({y for _, y in points})
        assert len(levels) == 3, levels
        top, zero, bottom = levels
        # Both spikes reach their full height, ±100 around the zero line, on a ±110 axis (the
        # residual panel is 100 units tall).
        assert zero - top > 40
        assert abs((zero - top) - (bottom - zero)) <= 1
        width = max(xs) - min(xs)
        for level, index in ((top, 31_337), (bottom, 77_777)):
            (x,) = {x for x, y in points if y == level}
            assert abs((x - min(xs)) / width - index / (n - 1)) < 2 / width


def test_path_data_the_page_already_holds_is_drawn_by_reference(
    results: list[dict[str, Any]],
) -> None:
    twin = copy.deepcopy(results[1])
    twin["name"] = "i3 trip A02 again"
    overlay = twin["signals"][0]["figures"]["overlay"]
    # A model input equal to its measurement: the two envelopes are the same path.
    overlay["sim_min"], overlay["sim_max"] = list(overlay["ref_min"]), list(overlay["ref_max"])
    html = render_html(_typed([*results, twin]), title="t", generated_utc=STAMP)
    assert html == render_html(
        _typed(copy.deepcopy([*results, twin])), title="t", generated_utc=STAMP
    )
    long_data = re.findall(r'\sd="([^"]{200,})"', html)
    assert long_data
    assert len(long_data) == len(set(long_data))
    ids = re.findall(r'<path id="([^"]+)"', html)
    assert len(ids) == len(set(ids))
    used = re.findall(r'<use class="[^"]+" href="#([^"]+)"/>', html)
    assert used
    assert set(used) <= set(ids)
    plots = re.findall(r'<svg class="hv-plot".*?</svg>', html, re.S)
    assert len(plots) == 5
    for plot in plots:
        for css in ("hv-ref", "hv-sim", "hv-res", "hv-match", "hv-xc", "hv-bar", "hv-cdf"):
            assert len(re.findall(rf'<(?:path|g|use) class="{css}"', plot)) == 1, css
    last = plots[-1]
    (ref_id,) = re.findall(r'<use class="hv-ref" href="#([^"]+)"', last)
    (sim_id,) = re.findall(r'<use class="hv-sim" href="#([^"]+)"', last)
    assert ref_id == sim_id


def test_glyph_plot_draws_every_lambda_and_rings_and_labels_the_worst(
    results: list[dict[str, Any]],
) -> None:
    from pytest_hevval.report import plots

    spec = copy.deepcopy(results[0])
    spec["signals"][0]["path"] = "E_batt/<b>&U"
    drawn = plots.glyph_plot(_typed_one(spec))
    assert drawn is not None
    assert drawn.startswith('<svg class="hv-glyph"')
    assert "<b>" not in drawn
    glyphs = re.findall(
        r'<circle class="hv-gl( fail)?" cx="([-\d.]+)" cy="[-\d.]+" r="([\d.]+)" '
        r'fill="(#\w+)"><title>([^<]*)</title></circle>',
        drawn,
    )
    points = model.glyph_points(_typed_one(spec))
    assert len(glyphs) == len(points) == 21
    by_title = {title: (ring, float(x), float(r), fill) for ring, x, r, fill, title in glyphs}
    assert len(by_title) == len(points)
    seen = []
    for p in points:
        name = p.characteristic
        title = f"{p.signal} · {model.SHORT_LABELS[name]} {model.LABELS[name]} {p.value:.4f}"
        ring, x, radius, fill = by_title[escape(title, quote=True)]
        assert ring == (" fail" if p.status == "fail" else "")
        assert fill == model.CHARACTERISTIC_COLOURS[name]
        seen.append((p.value, x, p.level, radius))
    # x grows with λ; a glyph of level 1 is larger than one of level 2.
    assert [x for _, x, _, _ in sorted(seen)] == sorted(x for _, x, _, _ in seen)
    radii = {level: radius for _, _, level, radius in seen}
    assert radii[1] > radii[2]
    labels = re.findall(r'<text class="hv-tag( fail)?"[^>]*>([^<]*)</text>', drawn)
    assert len(labels) == 6
    assert (" fail", "E_batt/P_batt · λ3 0.850") in labels
    assert (" fail", "E_batt · λ7 0.820") in labels
    assert ("", "E_batt/&lt;b&gt;&amp;U · λ2 0.900") in labels
    assert (
        plots.glyph_plot(_typed_one({"name": "empty", "spec": "e.yaml", "phi": 1.0, "signals": []}))
        is None
    )


def test_html_needs_jinja2(monkeypatch: pytest.MonkeyPatch, results: list[dict]) -> None:
    monkeypatch.setitem(sys.modules, "jinja2", None)
    with pytest.raises(MissingExtraError, match=r"pytest-hevval\[html\]"):
        render_html(_typed(results), title="t", generated_utc=STAMP)


def test_html_report_draws_without_matplotlib(
    monkeypatch: pytest.MonkeyPatch, results: list[dict]
) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    html = render_html(_typed(results), title="t", generated_utc=STAMP)
    assert html.count('<svg class="hv-glyph"') == 2


def test_importing_the_report_package_loads_no_plotting_or_templating() -> None:
    code = (
        "import sys, pytest_hevval.report as r; "
        "print(sorted(m for m in ('matplotlib', 'jinja2') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# --------------------------------------------------------------------------- files and options


def test_write_reports_writes_each_format_atomically(
    results: list[dict[str, Any]], tmp_path: Path
) -> None:
    directory = tmp_path / "deep" / "report"
    paths = write_reports(_typed(results), {"md", "json", "html"}, directory, title="T")
    assert [p.name for p in paths] == ["report.html", "report.json", "report.md"]
    assert sorted(p.name for p in directory.iterdir()) == [
        "report.html",
        "report.json",
        "report.md",
    ]
    assert json.loads((directory / "report.json").read_text("utf-8"))["summary"]["specs"] == 2
    umask = os.umask(0)
    os.umask(umask)
    # Permissions as for any new file (not mkstemp's 0600): others may serve the report.
    assert stat.S_IMODE((directory / "report.html").stat().st_mode) == 0o666 & ~umask
    assert (directory / "report.md").read_text("utf-8") == render_markdown(_typed(results))
    # Only the requested formats; an existing file is replaced.
    (directory / "report.md").write_text("old", "utf-8")
    assert write_reports(_typed(results), {"md"}, directory, title="T") == [directory / "report.md"]
    assert (directory / "report.md").read_text("utf-8") == render_markdown(_typed(results))


def test_write_reports_leaves_no_temporary_file_when_rendering_fails(
    results: list[dict[str, Any]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from pytest_hevval import files

    def broken(path: Path, text: str) -> None:
        raise OSError("disk full")

    (tmp_path / "report.json").write_text("previous", "utf-8")
    monkeypatch.setattr(files.os, "replace", lambda *a: broken(Path(), ""))
    with pytest.raises(OSError, match="disk full"):
        write_reports(_typed(results), {"json"}, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["report.json"]
    assert (tmp_path / "report.json").read_text("utf-8") == "previous"


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("html,json,md", {"html", "json", "md"}),
        (" HTML , md ", {"html", "md"}),
        ("markdown", {"md"}),
        ("json,json", {"json"}),
    ],
)
def test_parse_formats_accepts_known_names(value: str, expected: set[str]) -> None:
    assert parse_formats(value) == expected


def test_parse_formats_names_the_option_and_suggests_a_fix() -> None:
    with pytest.raises(ReportOptionError) as info:
        parse_formats("html,jsn")
    message = str(info.value)
    assert "--hevval-report" in message
    assert "'jsn'" in message
    assert "'json'" in message
    assert isinstance(info.value, HevvalError)
    assert isinstance(info.value, ValueError)
    with pytest.raises(ReportOptionError, match="comma-separated"):
        parse_formats(" , ")


def test_messages_name_the_report_option_as_the_front_end_spells_it() -> None:
    with pytest.raises(ReportOptionError) as info:
        parse_formats("html,jsn", COMMAND)
    assert str(info.value).startswith("--report: unknown report format 'jsn'")
    with pytest.raises(ReportOptionError, match=r"e\.g\. --report=html,json,md"):
        parse_formats(" , ", COMMAND)


def test_hevval_run_names_its_own_report_flag(tmp_path: Path) -> None:
    """``hevval run --report foo`` names ``--report``, the flag the user typed."""
    run = subprocess.run(
        [sys.executable, "-m", "pytest_hevval", "run", "specs", "--report", "foo"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 2, run.stderr
    assert "hevval run: error: --report: unknown report format 'foo'" in run.stderr
    assert "--hevval-report" not in run.stderr


def test_write_reports_rejects_unknown_formats(
    results: list[dict[str, Any]], tmp_path: Path
) -> None:
    with pytest.raises(ReportOptionError, match="'pdf'"):
        write_reports(_typed(results), {"pdf"}, tmp_path)
    assert not any(tmp_path.iterdir())


def test_an_origin_with_failing_descendants_names_both(results: list[dict[str, Any]]) -> None:
    child = results[0]["signals"][2]
    child["origins"] = ["E_batt/P_batt", "E_batt/P_batt/I_cell"]
    assert "| here, E_batt/P_batt/I_cell |" in render_markdown(_typed(results))
    annotation = github_annotations(_typed(results), ".")[1]
    assert annotation.endswith("(the error appears in this signal and E_batt/P_batt/I_cell)")


def test_only_this_runs_reports_stay_and_the_footer_names_what_was_written(
    results: list[dict[str, Any]], tmp_path: Path
) -> None:
    write_reports(_typed(results), {"html", "json", "md"}, tmp_path, generated_utc=STAMP)
    (tmp_path / "notes.txt").write_text("mine")
    written = write_reports(_typed(results), {"html"}, tmp_path, generated_utc=STAMP)
    assert [p.name for p in written] == ["report.html"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "report.html"]
    page = (tmp_path / "report.html").read_text("utf-8")
    assert "report.json" not in page
    write_reports(_typed(results), {"html", "json"}, tmp_path, generated_utc=STAMP)
    assert "the same data is in report.json" in (tmp_path / "report.html").read_text("utf-8")


def test_a_spec_that_fails_on_its_signals_says_so_under_its_phi(
    results: list[dict[str, Any]],
) -> None:
    passing_phi = copy.deepcopy(results[0])
    passing_phi["phi"] = 0.95
    passing_phi["min_phi"] = 0.9
    passing_phi["phi_passed"] = True
    passing_phi["passed"] = False
    page = render_html(_typed([passing_phi]), title="t", generated_utc=STAMP)
    assert "✘ FAIL on its signals" in page
    assert "2 spec files" not in page
    assert "1 spec file, 0 pass;" in page


def test_the_comparison_shows_the_worst_changes_and_every_change_behind_details() -> None:
    from pytest_hevval.report.comparison import COMPARISON_ROWS, comparison_markdown
    from pytest_hevval.results.changes import (
        Comparison,
        FieldDelta,
        SignalComparison,
        SpecComparison,
    )
    from pytest_hevval.results.verdict import RegressedItem, RunVerdict

    lambdas = tuple(FieldDelta(f"c{i}", 0.9, 0.9 - (i - 12) / 1000) for i in range(30) if i != 12)
    signal = SignalComparison("s<x>", "x", None, lambdas, (), None, None)
    spec = SpecComparison(
        "a|b.hevval.yaml", "b", FieldDelta("phi", 0.95, 0.95), None, None, (signal,), (), ()
    )
    comparison = Comparison("v1", "v2", (spec,), (), ())
    regression = RegressedItem("a|b.hevval.yaml", "s<x>", "c20", "a|b: c20 dropped")
    verdict = RunVerdict(passed=False, regressions=(regression,), baseline="v1 (…)")
    lines = comparison_markdown(comparison, verdict)
    assert lines[0] == "#### Compared with v1 (…)"
    assert lines[2] == "❌ 1 regression; 17 values of Φ and λ worse, 12 better."
    assert lines[4] == "- a\\|b: c20 dropped"
    rows = [line for line in lines if line.startswith("| ") and not line.startswith("| |")]
    shown = COMPARISON_ROWS + 5
    # The regression first, then the largest drops, then the largest rises.
    assert rows[0].startswith("| ❌ | `a\\|b.hevval.yaml::s&lt;x&gt;` | c20 | 0.9000 | 0.8920 |")
    assert [row.split(" | ")[2] for row in rows[1:4]] == ["c29", "c28", "c27"]
    assert [row.split(" | ")[2] for row in rows[COMPARISON_ROWS : COMPARISON_ROWS + 2]] == [
        "c0",
        "c1",
    ]
    assert "<details><summary>Every change (29)</summary>" in lines
    assert len(rows) == shown + 29

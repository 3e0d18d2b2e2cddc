"""The lag and the correlation at it: one definition, worded alike by every output.

The lag search maximises ρ(m), the mean-removed correlation of the simulation's fixed window
with the shifted reference (``core/lag.py``); every output prints ρ at the lag and at zero lag,
so the value at the lag is never below the one at zero lag, and a lag on the edge of the
search says so and names the wider ``alignment: {max_lag_s: …}``.
"""

from __future__ import annotations

import html
import json
import re

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_hevval.core.characteristics import SignalCharacteristics, signal_characteristics
from pytest_hevval.core.lag import _EXACT_LIMIT, correlation_curve, search_lag, window_correlations
from pytest_hevval.report.sentences import lag_bound_text, lag_text
from tests.strategies import signal_pairs

pytest_plugins = ["pytester"]

DT = 0.1
DELAY_S = 8.0
MAX_LAG_S = 3.0

SPEC = f"""\
name: delayed
reference: {{path: data/ref.csv, time: t}}
model: {{path: data/sim.csv, time: t}}
alignment: {{max_lag_s: {MAX_LAG_S:g}}}
thresholds: {{lag_correlation: 0.999, mae: 0.99}}
sets:
  - {{signal: x, unit: kW}}
"""


def _smooth(n: int, seed: int) -> np.ndarray:
    """A slowly varying, nonzero-mean random signal: noise averaged over 300 samples, so that
    its correlation with itself falls slowly with the shift."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(size=n + 300)
    return np.convolve(noise, np.ones(300) / 30, mode="valid")[:n] + 40


def _delayed_pair(n: int, delay: int, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """(reference, simulation) where the simulation is the reference ``delay`` samples late."""
    base = _smooth(n + delay, seed)
    return base[delay:], base[:n]


def test_lag_beyond_the_search_is_on_its_edge_in_the_failure_report_and_the_html_panel(
    pytester: pytest.Pytester,
) -> None:
    n = 3000
    reference, simulated = _delayed_pair(n, round(DELAY_S / DT))
    t = np.arange(n) * DT
    (pytester.path / "data").mkdir()
    pd.DataFrame({"t": t, "x": reference}).to_csv(pytester.path / "data/ref.csv", index=False)
    pd.DataFrame({"t": t, "x": simulated}).to_csv(pytester.path / "data/sim.csv", index=False)
    pytester.makefile(".hevval.yaml", delayed=SPEC)

    result = pytester.runpytest("--hevval", "--hevval-no-history", "--hevval-report=html,json")

    result.assert_outcomes(failed=1, passed=1)
    out = result.stdout.str()
    lines = [line.strip() for line in out.splitlines() if line.strip().startswith("lag ")]
    assert len(lines) == 1, out
    line = lines[0]
    # The simulation lags by 8 s; the ±3 s search stops at −3 s and says so.
    assert line.startswith(f"lag -{MAX_LAG_S:g} s, where the mean-removed correlation peaks: ")
    assert f"on the edge of the ±{MAX_LAG_S:g} s search" in line
    assert f"alignment: {{max_lag_s: {2 * MAX_LAG_S:g}}}" in line
    peak, zero = (float(v) for v in re.findall(r"\d\.\d{4}", line)[:2])
    assert peak >= zero

    folder = pytester.path / ".hevval" / "report"
    signal = json.loads((folder / "report.json").read_text())["specs"][0]["signals"][0]
    assert signal["lag_s"] == pytest.approx(-MAX_LAG_S)
    assert signal["lag_at_bound"] is True
    assert signal["max_lag_s"] == pytest.approx(MAX_LAG_S)
    assert signal["peak_correlation"] >= signal["correlation_at_zero_lag"]
    # The JSON holds the numbers the terminal printed.
    assert lag_text(signal) == line
    correlation = signal["figures"]["correlation"]
    assert correlation["peak_lag_s"] == pytest.approx(signal["lag_s"])
    assert correlation["peak"] == pytest.approx(signal["peak_correlation"], abs=1e-6)
    assert correlation["zero_lag"] == pytest.approx(signal["correlation_at_zero_lag"], abs=1e-6)
    assert correlation["at_bound"] is True

    # The HTML panel shows the very sentence, and its figure marks the same peak.
    page = html.unescape((folder / "report.html").read_text())
    assert line in page
    assert f"peak {peak:.4f} at -{MAX_LAG_S:g} s · {zero:.4f} at 0 s · on the search edge" in page


def test_a_lag_inside_the_search_says_nothing_of_an_edge() -> None:
    reference, simulated = _delayed_pair(3000, 5)
    chars = signal_characteristics(reference, simulated, dt=DT, max_lag_s=MAX_LAG_S)
    assert chars.lag_s == pytest.approx(-0.5)
    assert not chars.lag_at_bound
    # An exact shift, centred on the two records' own means: all but 1.
    assert chars.peak_correlation > 0.9999
    text = lag_text(chars.as_dict())
    assert text == (
        f"lag -0.5 s, where the mean-removed correlation peaks: {chars.peak_correlation:.4f} "
        f"({chars.correlation_at_zero_lag:.4f} at zero lag)"
    )


@settings(max_examples=150, deadline=None)
@given(
    pair=signal_pairs(min_size=3, max_size=400), max_lag_s=st.sampled_from([None, 0.0, 0.3, 5.0])
)
def test_the_correlation_at_the_lag_is_never_below_the_one_at_zero_lag(
    pair: tuple[np.ndarray, np.ndarray], max_lag_s: float | None
) -> None:
    reference, simulated = pair
    chars = signal_characteristics(reference, simulated, dt=DT, max_lag_s=max_lag_s)
    assert 0.0 <= chars.correlation_at_zero_lag <= chars.peak_correlation <= 1.0
    search = chars.lag_search
    assert search is not None
    # The printed pair is the maximised quantity itself: the exact curve peaks there.
    if search.max_lag:
        curve = window_correlations(reference, simulated, search.max_lag)
        assert chars.peak_correlation == pytest.approx(float(curve.max()), abs=1e-6)
        assert chars.correlation_at_zero_lag == pytest.approx(
            float(curve[search.max_lag]), abs=1e-6
        )
    assert chars.lag_at_bound == (search.max_lag > 0 and abs(search.lag) == search.max_lag)


def test_the_long_record_search_reports_the_same_quantity_and_its_edge() -> None:
    """Past 2^18 samples the search goes coarse to fine; the zero-lag value then needs its own
    exact sum, and the edge and the ordering hold as on the exact path."""
    n = _EXACT_LIMIT + 40_000
    reference, simulated = _delayed_pair(n, 400, seed=11)
    found = search_lag(reference, simulated, 300)
    assert found.method == "pyramid"
    assert (found.lag, found.at_bound) == (-300, True)
    assert found.correlation >= found.zero_lag_correlation
    exact = window_correlations(reference, simulated, 300)
    assert found.correlation == pytest.approx(float(exact[0]), abs=1e-9)
    assert found.zero_lag_correlation == pytest.approx(float(exact[300]), abs=1e-9)

    # Scored, the zero-lag value comes from the main pass's whole-record sums less the ends.
    chars = signal_characteristics(reference, simulated, dt=DT, max_lag_s=300 * DT)
    assert chars.lag_search is not None
    assert chars.lag_search.method == "pyramid"
    assert (chars.lag_s, chars.lag_at_bound) == (pytest.approx(-300 * DT), True)
    assert chars.peak_correlation == pytest.approx(float(exact[0]), abs=1e-9)
    assert chars.correlation_at_zero_lag == pytest.approx(float(exact[300]), abs=1e-9)

    inside = search_lag(*_delayed_pair(n, 120, seed=11), 300)
    assert (inside.lag, inside.at_bound) == (-120, False)
    assert inside.correlation > 0.9999


def test_the_display_curve_is_the_searched_quantity() -> None:
    reference, simulated = _delayed_pair(2000, 7)
    lags, curve = correlation_curve(reference, simulated, 30)
    found = search_lag(reference, simulated, 30)
    assert int(lags[np.argmax(curve)]) == found.lag == -7
    assert float(curve.max()) == pytest.approx(found.correlation, abs=1e-12)
    assert float(curve[lags == 0][0]) == pytest.approx(found.zero_lag_correlation, abs=1e-12)


@pytest.mark.parametrize(
    ("found", "expected"),
    [
        ({"lag_at_bound": False, "max_lag_s": 5.0}, ""),
        (
            {"lag_at_bound": True, "max_lag_s": 5.0, "n_samples": 6000, "dt": 0.1},
            "on the edge of the ±5 s search, so the peak may lie beyond it: widen it in the spec, "
            "alignment: {max_lag_s: 10}",
        ),
        # The search reaches at most a quarter of the record (150 s here).
        (
            {"lag_at_bound": True, "max_lag_s": 100.0, "n_samples": 6000, "dt": 0.1},
            "on the edge of the ±100 s search, so the peak may lie beyond it: widen it in the "
            "spec, alignment: {max_lag_s: 150}",
        ),
        (
            {"lag_at_bound": True, "max_lag_s": 150.0, "n_samples": 6000, "dt": 0.1},
            "on the edge of the ±150 s search, so the peak may lie beyond it; the search already "
            "spans a quarter of the record, so shift the model's time in the spec "
            "(alignment: {offset_s: …}) or score a longer record",
        ),
        # A diagnosis payload carries no record length.
        (
            {"lag_at_bound": True, "max_lag_s": 3.0},
            "on the edge of the ±3 s search, so the peak may lie beyond it: widen it in the spec, "
            "alignment: {max_lag_s: 6}",
        ),
    ],
)
def test_the_edge_words(found: dict[str, object], expected: str) -> None:
    assert lag_bound_text(found) == expected


def test_results_written_before_the_zero_lag_value_existed_still_read_and_print() -> None:
    old = {
        "lambdas": [0.9] * 6,
        "lag_s": -0.2,
        "peak_correlation": 0.99,
        "mae": 1.0,
        "rms": 2.0,
    }
    chars = SignalCharacteristics.from_dict(old)
    assert np.isnan(chars.correlation_at_zero_lag)
    assert not chars.lag_at_bound
    assert (
        lag_text(chars.as_dict()) == "lag -0.2 s, where the mean-removed correlation peaks: 0.9900"
    )

"""The field's standard metrics: golden values from their sources, the reference package for
ISO/TS 18571, Hypothesis properties, degenerate inputs, and a spec end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pytest_hevval.core.characteristics import signal_characteristics
from pytest_hevval.core.registry import (
    STANDARD_CHARACTERISTICS,
    compute_characteristic,
    default_characteristics,
    get_characteristic,
    select_characteristics,
)
from pytest_hevval.core.standard import (
    GUIDELINE14_HOURLY_THRESHOLDS,
    bounded_efficiency,
    calibration_errors,
    iso18571_rating,
    kge,
    nse,
    russell,
    sprague_geers,
    theil_u,
)
from pytest_hevval.core.standard._moments import CANCELLATION_BITS, Moments, moments_from_pass
from pytest_hevval.core.standard.kge import nse_from_moments
from pytest_hevval.errors import DegenerateSignalError
from pytest_hevval.report.sentences import failure_lines
from tests.strategies import signal_pairs
from tests.test_plugin import write_data

pytest_plugins = ["pytester"]

EXAMPLE = Path(__file__).resolve().parent.parent / "example_project"


def _decaying_sine(n: int, *, delay: float = 0.0, gain: float = 1.0) -> np.ndarray:
    """Schwer's (2007) idealised response m(t) = e^{−t} sin 2πt, on 0 ≤ t < 2, delayed by τ."""
    t = np.linspace(0.0, 2.0, n, endpoint=False) - delay
    return gain * np.where(t >= 0, np.exp(-t) * np.sin(2 * np.pi * t), 0.0)


def _crash_pulse(n: int, *, peak: float = 1.0, width: float = 0.3, at: float = 0.4) -> np.ndarray:
    """A half-sine deceleration pulse, the shape ISO/TS 18571 rates (sled and crash tests)."""
    t = np.linspace(0.0, 1.0, n)
    phase = (t - at + width / 2) / width
    return peak * np.where((phase > 0) & (phase < 1), np.sin(np.pi * phase), 0.0)


def _iso_pairs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(18571)
    n = 800
    ref = _decaying_sine(n)
    pulse = _crash_pulse(n)
    return {
        "gain": (ref, _decaying_sine(n, gain=1.2)),
        "delay": (ref, _decaying_sine(n, delay=0.05)),
        "lead": (ref, np.roll(ref, -30)),
        "noise": (ref, ref + rng.normal(0.0, 0.05, n)),
        "pulse-late-and-low": (pulse, _crash_pulse(n, peak=0.85, at=0.43)),
        "pulse-wide": (pulse, _crash_pulse(n, width=0.36) + 0.02),
        "far-off": (pulse, -0.5 * pulse + 0.3),
    }


@pytest.fixture(scope="module")
def i3_pairs() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Measured and modelled signals of the i3 motorway trip, as the example scores them."""
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import load_spec

    spec = load_spec(EXAMPLE / "specs" / "i3-A02-motorway-v2.hevval.yaml")
    return evaluate_spec(spec, rootdir=EXAMPLE, keep_arrays=True).arrays


# The package's scores per curve pair, computed once for both kernel paths.
_PACKAGE_SCORES: dict[str, tuple[float, ...]] = {}


def _package_scores(ref: np.ndarray, sim: np.ndarray, key: str = "") -> tuple[float, ...]:
    if key in _PACKAGE_SCORES:
        return _PACKAGE_SCORES[key]
    from objective_rating_metrics.rating import ISO18571

    t = np.arange(ref.size) * 1e-4
    iso = ISO18571(np.c_[t, ref], np.c_[t, sim])
    scores = (
        iso.overall_rating(-1),
        iso.corridor_rating(-1),
        iso.phase_rating(-1),
        iso.magnitude_rating(-1),
        iso.slope_rating(-1),
    )
    if key:
        _PACKAGE_SCORES[key] = scores
    return scores


def _scores(ref: np.ndarray, sim: np.ndarray) -> tuple[float, ...]:
    r = iso18571_rating(ref, sim)
    return (r.rating, r.corridor, r.phase, r.magnitude, r.slope)


# --- ISO/TS 18571 --------------------------------------------------------------------------


# The package compiles its DTW with numba on first use (about 20 s, not cached on disk).
@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(_iso_pairs()))
def test_iso18571_equals_the_reference_package(case: str, kernel_path: str) -> None:
    ref, sim = _iso_pairs()[case]
    assert _scores(ref, sim) == pytest.approx(_package_scores(ref, sim, case), abs=1e-3)


@pytest.mark.slow
@pytest.mark.parametrize("signal", ["E_batt/P_batt", "E_batt/P_batt/U_batt"])
def test_iso18571_equals_the_reference_package_on_a_real_i3_pair(
    i3_pairs: dict[str, tuple[np.ndarray, np.ndarray]], signal: str, kernel_path: str
) -> None:
    # 150 s of the motorway trip at 10 Hz: the package's n × n distance matrix must fit.
    ref, sim = (a[6000:7500] for a in i3_pairs[signal])
    assert _scores(ref, sim) == pytest.approx(_package_scores(ref, sim, signal), abs=1e-3)


def test_iso18571_identical_curves_score_one_in_every_part() -> None:
    ref = _decaying_sine(500)
    assert _scores(ref, ref.copy()) == (1.0, 1.0, 1.0, 1.0, 1.0)


@pytest.mark.parametrize("shift", [-40, -7, 12, 60])
def test_iso18571_phase_score_is_the_standards_linear_ramp(shift: int) -> None:
    # ISO/TS 18571 5.3: E_P = (ε_P·N − |n_ε|)/(ε_P·N) with k_P = 1, ε_P = 0.2.
    n = 1000
    base = np.sin(np.linspace(0, 3 * np.pi, n + 200)) * np.hanning(n + 200)
    ref = base[100 : 100 + n]
    sim = base[100 - shift : 100 - shift + n]
    rating = iso18571_rating(ref, sim)
    assert rating.shift == -shift
    assert rating.phase == pytest.approx(1 - abs(shift) / (0.2 * n))


def test_iso18571_refuses_curves_the_phase_shift_leaves_too_short_for_the_slope() -> None:
    # Ten samples may shift by two, leaving eight: fewer than the slope's nine-sample average.
    ref = np.array([0.0, 0.0, 0.0, 1.0, 3.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(DegenerateSignalError, match="overlap in 8 samples after the phase shift"):
        iso18571_rating(ref, np.roll(ref, 2))


def test_iso18571_banded_approximation_stays_near_the_exact_score(
    i3_pairs: dict[str, tuple[np.ndarray, np.ndarray]], kernel_path: str
) -> None:
    ref, sim = i3_pairs["E_batt/P_batt"]
    exact = iso18571_rating(ref, sim)
    assert not exact.banded
    # The band a 360,000-sample record gets from EXACT_DTW_CELLS: 88 samples each side.
    banded = iso18571_rating(ref, sim, max_cells=ref.size * 177)
    assert banded.banded
    assert banded.band == 88
    assert abs(banded.rating - exact.rating) < 2e-3  # docs/metrics.md: measured 0.0011


# --- Theil's U -----------------------------------------------------------------------------


def test_theil_u_is_one_for_a_zero_or_opposite_forecast() -> None:
    # Theil (1966): U = 1 for a model predicting 0, and for one negatively proportional.
    ref = np.sin(np.linspace(0, 6, 300)) + 0.3
    assert theil_u(ref, np.zeros_like(ref)).u == pytest.approx(1.0)
    assert theil_u(ref, -2.5 * ref).u == pytest.approx(1.0)


def test_theil_proportions_name_the_kind_of_error() -> None:
    ref = np.sin(np.linspace(0, 12 * np.pi, 1200))
    assert theil_u(ref, ref + 0.2).bias == pytest.approx(1.0)
    assert theil_u(ref, 1.3 * ref).variance == pytest.approx(1.0, abs=1e-9)
    shifted = np.sin(np.linspace(0, 12 * np.pi, 1200) + 0.3)
    assert theil_u(ref, shifted).covariance == pytest.approx(1.0, abs=1e-3)


@settings(max_examples=60, deadline=None)
@given(signal_pairs(), st.floats(1e-3, 1e3))
def test_theil_proportions_sum_to_one_and_u_ignores_units(
    pair: tuple[np.ndarray, np.ndarray], k: float
) -> None:
    ref, sim = pair
    t = theil_u(ref, sim)
    assume(t.u > 1e-9)
    assert t.bias + t.variance + t.covariance == pytest.approx(1.0)
    assert 0.0 <= t.u <= 1.0
    assert theil_u(k * ref, k * sim).u == pytest.approx(t.u, rel=1e-9, abs=1e-12)


# --- Sprague–Geers and Russell -------------------------------------------------------------


@pytest.mark.parametrize("gain", [0.8, 1.2, 2.0])
def test_sprague_geers_magnitude_is_the_gain_error(gain: float) -> None:
    # Sprague & Geers (2004): c = k·m gives M = k − 1 exactly and P = 0.
    m = _decaying_sine(1000)
    e = sprague_geers(m, gain * m)
    assert e.magnitude == pytest.approx(gain - 1)
    assert e.phase == pytest.approx(0.0, abs=1e-7)
    assert e.combined == pytest.approx(abs(gain - 1))


@pytest.mark.parametrize("phi", [0.1, 0.5, 2.0])
def test_sprague_geers_phase_is_the_phase_angle_over_pi(phi: float) -> None:
    # Over whole periods, ψ_mc/√(ψ_mm ψ_cc) = cos φ, so P = φ/π (Geers 1984).
    t = np.linspace(0, 4 * 2 * np.pi, 4000, endpoint=False)
    e = sprague_geers(np.sin(t), np.sin(t + phi))
    assert e.phase == pytest.approx(phi / np.pi, abs=1e-9)
    assert e.magnitude == pytest.approx(0.0, abs=1e-9)


def test_russell_of_a_twenty_percent_gain() -> None:
    # Schwer (2007) eq. 4–7 on the +20 % magnitude case of his idealised response, c = 1.2·m:
    # m_r = (1.44 − 1)/1.2, RM = log₁₀(1 + m_r) = 0.1357, RP = 0, RC = √(π/4)·RM = 0.1203.
    m = _decaying_sine(1000)
    e = russell(m, 1.2 * m)
    assert e.magnitude == pytest.approx(math.log10(1 + 0.44 / 1.2))
    assert e.combined == pytest.approx(math.sqrt(math.pi / 4) * math.log10(1 + 0.44 / 1.2))
    assert e.combined == pytest.approx(0.1203, abs=1e-4)
    low = russell(m, 0.8 * m)
    assert low.magnitude == pytest.approx(-math.log10(1 + 0.36 / 0.8))


@settings(max_examples=60, deadline=None)
@given(signal_pairs(), st.floats(1e-3, 1e3))
def test_sprague_geers_and_russell_ignore_units(
    pair: tuple[np.ndarray, np.ndarray], k: float
) -> None:
    ref, sim = pair
    # Magnitudes whose ratio stays inside the float range whatever k (subnormals need not).
    assume(np.abs(sim).max() > 1e-150)
    for metric in (sprague_geers, russell):
        plain, scaled = metric(ref, sim), metric(k * ref, k * sim)
        assert scaled.combined == pytest.approx(plain.combined, rel=1e-7, abs=1e-9)


# --- KGE and NSE ---------------------------------------------------------------------------


def test_kge_parts_of_a_known_model() -> None:
    # s = 1.1·o + 0.2 with o of mean 2: r = 1, α = 1.1, β = (2.2 + 0.2)/2 = 1.2.
    o = 2.0 + np.sin(np.linspace(0, 8 * np.pi, 2000, endpoint=False))
    k = kge(o, 1.1 * o + 0.2)
    assert (k.r, k.variability, k.beta) == pytest.approx((1.0, 1.1, 1.2))
    assert k.kge == pytest.approx(1 - math.hypot(0.1, 0.2))
    # Kling et al. (2012): γ = CV_s/CV_o = (1.1σ/2.4)/(σ/2).
    assert kge(o, 1.1 * o + 0.2, form=2012).variability == pytest.approx(1.1 * 2 / 2.4)


def test_nse_of_the_mean_is_zero_and_bounded_score_is_one_half() -> None:
    # Nash & Sutcliffe (1970): the observations' mean as the model scores NSE = 0.
    o = np.cos(np.linspace(0, 9, 500)) + 4
    assert nse(o, np.full_like(o, o.mean())) == pytest.approx(0.0, abs=1e-12)
    assert bounded_efficiency(0.0) == 0.5
    assert bounded_efficiency(1.0) == 1.0


@settings(max_examples=60, deadline=None)
@given(signal_pairs())
def test_nse_is_guptas_decomposition(pair: tuple[np.ndarray, np.ndarray]) -> None:
    # Gupta et al. (2009) eq. 4: NSE = 2αr − α² − β_n², β_n = (μ_s − μ_o)/σ_o.
    o, s = pair
    assume(np.std(s) > 1e-9 * (np.abs(s).max() + 1))
    assume(abs(o.mean()) > 1e-6 * np.abs(o).max())
    k = kge(o, s)
    beta_n = (s.mean() - o.mean()) / o.std()
    expected = 2 * k.variability * k.r - k.variability**2 - beta_n**2
    assert nse(o, s) == pytest.approx(expected, rel=1e-6, abs=1e-6 * max(1.0, abs(expected)))


@settings(max_examples=60, deadline=None)
@given(signal_pairs(), st.floats(1e-3, 1e3), st.floats(-1e3, 1e3))
def test_nse_ignores_units_and_offsets(
    pair: tuple[np.ndarray, np.ndarray], k: float, shift: float
) -> None:
    o, s = pair
    before = nse(o, s)
    after = nse(k * o + shift, k * s + shift)
    assert after == pytest.approx(before, rel=1e-6, abs=1e-6)


# --- CV(RMSE) and NMBE ---------------------------------------------------------------------


def test_constant_bias_gives_guideline14_errors() -> None:
    # Guideline 14 with p = 1: a model low by b everywhere has NMBE = n·b/((n − 1)ȳ) and
    # CV(RMSE) = |b|·√(n/(n − 1))/ȳ, in percent.
    n = 400
    y = 50 + 10 * np.sin(np.linspace(0, 20, n))
    e = calibration_errors(y, y - 2.0)
    assert e.nmbe == pytest.approx(100 * n * 2.0 / ((n - 1) * y.mean()))
    assert e.cv_rmse == pytest.approx(100 * 2.0 * math.sqrt(n / (n - 1)) / y.mean())


def test_guideline14_hourly_criteria_are_thresholds() -> None:
    assert pytest.approx({"nmbe": 0.90, "cvrmse": 0.70}) == GUIDELINE14_HOURLY_THRESHOLDS
    assert get_characteristic("cvrmse").default_weight == 0.0
    assert get_characteristic("nmbe").default_weight == 0.0


# --- every standard metric -----------------------------------------------------------------


def test_standard_metrics_are_off_by_default_and_on_when_named() -> None:
    defaults = {c.name for c in default_characteristics()}
    assert not defaults & set(STANDARD_CHARACTERISTICS)
    chosen = {c.name for c in select_characteristics(["iso18571", "theil"])}
    assert {"iso18571", "theil"} <= chosen
    assert "kge" not in chosen


@settings(max_examples=40, deadline=None)
@given(signal_pairs(min_size=12, max_size=200))
def test_perfect_agreement_scores_one(pair: tuple[np.ndarray, np.ndarray]) -> None:
    ref, _ = pair
    assume(abs(ref.mean()) > 1e-6 * np.abs(ref).max())
    for name in STANDARD_CHARACTERISTICS:
        scored = compute_characteristic(get_characteristic(name), ref, ref.copy(), 0.1)
        assert scored.value == pytest.approx(1.0), name


@settings(max_examples=30, deadline=None)
@given(signal_pairs(min_size=12, max_size=120), st.integers(-30, 30))
def test_every_standard_metric_ignores_a_change_of_units(
    pair: tuple[np.ndarray, np.ndarray], exponent: int
) -> None:
    # A power of two changes every value exactly, so even the warping path's ties stay put;
    # values stay normal floats whatever the power (subnormals would lose bits).
    ref, sim = pair
    assume(np.abs(sim).max() > 1e-150)
    k = 2.0**exponent
    for name in STANDARD_CHARACTERISTICS:
        characteristic = get_characteristic(name)
        try:
            plain = compute_characteristic(characteristic, ref, sim, 0.1)
        except DegenerateSignalError:
            with pytest.raises(DegenerateSignalError):
                compute_characteristic(characteristic, k * ref, k * sim, 0.1)
            continue
        scaled = compute_characteristic(characteristic, k * ref, k * sim, 0.1)
        assert scaled.value == pytest.approx(plain.value, rel=1e-9, abs=1e-12), name


@pytest.mark.parametrize("name", STANDARD_CHARACTERISTICS)
@pytest.mark.parametrize(
    ("ref", "sim", "says"),
    [
        (np.full(50, 3.0), np.arange(50.0), "reference is constant"),
        (np.r_[np.arange(20.0), np.nan], np.arange(21.0), "NaN or inf"),
        (np.arange(20.0), np.arange(21.0), "equal length"),
        (np.arange(2.0), np.arange(2.0), "samples are needed"),
    ],
    ids=["constant", "nan", "length", "short"],
)
def test_degenerate_inputs_are_refused_like_lambda1_to_6(
    name: str, ref: np.ndarray, sim: np.ndarray, says: str
) -> None:
    with pytest.raises(DegenerateSignalError, match=says):
        compute_characteristic(get_characteristic(name), ref, sim, 0.1)


@pytest.mark.parametrize("name", ["kge", "kge2012", "cvrmse", "nmbe"])
def test_mean_normalised_metrics_refuse_a_zero_mean_reference(name: str) -> None:
    ref = np.sin(np.linspace(0, 2 * np.pi, 100, endpoint=False))
    with pytest.raises(DegenerateSignalError, match="mean is 0"):
        compute_characteristic(get_characteristic(name), ref - ref.mean(), ref + 0.1, 0.1)


# --- from the λ pass's sums -----------------------------------------------------------------

#: The metrics the engine scores from the λ pass's sums (all but ISO/TS 18571's warping).
FROM_MOMENTS = tuple(
    name
    for name in STANDARD_CHARACTERISTICS
    if getattr(get_characteristic(name).compute, "from_moments", False)
)


def _from_pass(ref: np.ndarray, sim: np.ndarray) -> Moments:
    sums = signal_characteristics(ref, sim, dt=0.1, max_lag_s=0.0).sums
    assert sums is not None
    return moments_from_pass(sums, ref, sim)


def test_every_standard_metric_but_the_warping_one_is_scored_from_moments() -> None:
    assert set(FROM_MOMENTS) == set(STANDARD_CHARACTERISTICS) - {"iso18571"}


@settings(max_examples=60, deadline=None)
@given(
    signal_pairs(min_size=12, max_size=300),
    st.sampled_from([0.0, 1e3, -1e5, 3e7]),
    st.sampled_from([-900, 0, 600]),
)
def test_metrics_from_the_pass_equal_those_from_the_samples(
    pair: tuple[np.ndarray, np.ndarray], offset: float, exponent: int
) -> None:
    # Offsets far above the spread take the centring on the samples; powers of two far from 1
    # take the λ pass's rescaled sums.
    ref, sim = (np.ldexp(x + offset, exponent) for x in pair)
    assume(np.ptp(ref) > 0)
    moments = _from_pass(ref, sim)
    for name in FROM_MOMENTS:
        characteristic = get_characteristic(name)
        try:
            expected = compute_characteristic(characteristic, ref, sim, 0.1)
        except DegenerateSignalError:
            with pytest.raises(DegenerateSignalError):
                compute_characteristic(characteristic, ref, sim, 0.1, moments)
            continue
        got = compute_characteristic(characteristic, ref, sim, 0.1, moments)
        assert got.value == pytest.approx(expected.value, rel=1e-9, abs=1e-12), name
        for part, value in expected.components.items():
            tolerance = 1e-9 * max(1.0, abs(value)) + _split_rounding(name, part, ref, sim)
            assert got.components[part] == pytest.approx(value, abs=tolerance), (name, part)


def _split_rounding(name: str, part: str, ref: np.ndarray, sim: np.ndarray) -> float:
    """What rounding alone may move Theil's U_S and U_C by: they hold (σ_s − σ_r)², and each
    σ from the pass's sums may carry 2^CANCELLATION_BITS roundings of σ, which the difference
    of two nearly equal σ magnifies by σ / |σ_s − σ_r| (a pair alike in spread but not in
    shape is ill-conditioned for the split, on any path)."""
    if name != "theil" or part not in ("U_S", "U_C"):
        return 0.0
    peak = max(np.max(np.abs(ref)), np.max(np.abs(sim)))
    r, s = ref / peak, sim / peak
    sigma_r, sigma_s = float(np.std(r)), float(np.std(s))
    mse = float(np.mean((r - s) ** 2))
    if mse == 0.0:
        return 0.0  # a perfect model: every proportion is 0 on both paths
    rounding = 4 * 2.0**CANCELLATION_BITS * np.finfo(float).eps * max(sigma_r, sigma_s)
    return 2 * abs(sigma_s - sigma_r) * rounding / mse


def test_a_mean_that_dwarfs_the_spread_is_centred_on_the_samples() -> None:
    # Σx² − (Σx)²/n would lose about 40 bits here: NSE from it would be wrong in the 4th digit.
    t = np.linspace(0.0, 60.0, 6001)
    ref = 1e6 + np.sin(t)
    sim = 1e6 + 0.9 * np.sin(t - 0.05)
    moments = _from_pass(ref, sim)
    assert moments.ref_m2 == pytest.approx(float(np.sum((ref - ref.mean()) ** 2)), rel=1e-9)
    assert nse_from_moments(moments) == pytest.approx(nse(ref, sim), rel=1e-9)


def test_a_constant_reference_with_a_declared_range_is_refused_by_the_metrics() -> None:
    # λ1–λ6 accept it with a range; the standard metrics refuse it as on the samples.
    ref, sim = np.full(50, 3.0), np.linspace(2.0, 4.0, 50)
    sums = signal_characteristics(ref, sim, dt=0.1, reference_range=1.0).sums
    assert sums is not None
    moments = moments_from_pass(sums, ref, sim)
    for name in FROM_MOMENTS:
        with pytest.raises(DegenerateSignalError, match="reference is constant"):
            compute_characteristic(get_characteristic(name), ref, sim, 0.1, moments)


REAL_SPEC = """\
name: i3 B03 against itself, perturbed
reference: {path: %s, time: "Time [s]"}
model: {path: %s, time: "Time [s]"}
metrics: [theil, sprague_geers, russell, kge, kge2012, nse, cvrmse, nmbe]
sets:
  - signal: voltage
    ref: "`Battery Voltage [V]`"
    sim: "1.002 * `Battery Voltage [V]` - 0.4"
    children:
      - signal: soc
        ref: "`SoC [%%]`"
        sim: "`SoC [%%]` + 0.3"
      - signal: speed
        ref: "`Velocity [km/h]`"
        sim: "0.97 * `Velocity [km/h]` + 0.2 * `Throttle [%%]`"
      - signal: cabin
        ref: "`Battery Temperature [°C]` + 273.15"
        sim: "`Ambient Temperature [°C]` + 280.0"
"""


# P = arccos(cos θ)/π: near θ = 0 a rounding δ of cos θ moves P by up to √(2δ)/π, about 5e-8
# for δ = 1e-14, on the samples as on the sums.
_PHASE_ROUNDING = 1e-7


def test_the_engine_scores_metrics_on_a_real_trip_as_the_samples_do() -> None:
    # Battery voltage and temperatures in kelvin have means far above their spread: they take
    # the centring on the samples; speed does not.
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import parse_spec_text

    trip = EXAMPLE / "data" / "i3" / "TripB03.parquet"
    spec = parse_spec_text(REAL_SPEC % (trip, trip), EXAMPLE / "real.hevval.yaml")
    evaluation = evaluate_spec(spec, keep_arrays=True, intervals=False)
    assert len(evaluation.arrays) == 4
    for signal in evaluation.result.signals:
        ref, sim = evaluation.arrays[signal.path]
        for name in FROM_MOMENTS:
            expected = compute_characteristic(get_characteristic(name), ref, sim, 0.1)
            assert signal.lambdas[name] == pytest.approx(expected.value, rel=1e-9), name
            for part, value in expected.components.items():
                assert signal.components[name][part] == pytest.approx(
                    value, rel=1e-9, abs=_PHASE_ROUNDING if part.endswith("P") else 1e-12
                ), (signal.path, name, part)


# --- end to end ----------------------------------------------------------------------------

SPEC = """\
name: pack
reference: {path: data/ref.csv, time: t}
model: {path: data/sim.csv, time: time}
metrics: [iso18571, theil]
thresholds: {mae: 0.5, iso18571: 0.5}
sets:
  - signal: P
    ref: V * I
    unit: W
    children:
      - {signal: V, unit: V}
      - {signal: I, unit: A}
"""


@pytest.mark.parametrize("xdist", [False, True], ids=["serial", "xdist"])
def test_spec_with_standard_metrics_end_to_end(pytester: pytest.Pytester, xdist: bool) -> None:
    pytester.makefile(".hevval.yaml", pack=SPEC)
    write_data(pytester.path)
    extra = ["-n", "2"] if xdist else []
    result = pytester.runpytest(
        "--hevval", "--hevval-details", "--hevval-report=html,json,md", *extra
    )
    result.assert_outcomes(passed=4)
    result.stdout.fnmatch_lines(
        ["*ISO/TS 18571 rating 0.9*(corridor *, phase *, magnitude *, slope *", "*Theil's U 0.9*"]
    )
    report = pytester.path / ".hevval" / "report"
    data = json.loads((report / "report.json").read_text())
    signal = data["specs"][0]["signals"][0]
    assert set(signal["lambdas"]) >= {"iso18571", "theil"}
    assert set(signal["components"]["theil"]) == {"U", "U_M", "U_S", "U_C"}
    assert signal["thresholds"]["iso18571"] == 0.5
    html = (report / "report.html").read_text()
    assert "standard metrics" in html
    assert "U_M" in html
    assert "Standard metrics of pack" in (report / "report.md").read_text()


def test_a_standard_metric_below_its_threshold_fails_the_signal(tmp_path: Path) -> None:
    from pytest_hevval.scoring.engine import evaluate_spec
    from pytest_hevval.spec.load import parse_spec_text

    write_data(tmp_path, fault="leaf")
    text = SPEC.replace("iso18571: 0.5", "theil: 0.99")
    result = evaluate_spec(parse_spec_text(text, tmp_path / "pack.hevval.yaml")).result
    current = result.signal("P/I")
    assert [f.characteristic for f in current.failures] == ["theil"]
    assert current.components["theil"]["U_M"] > 0.5  # the injected fault is mostly an offset
    assert "1−U Theil's U = " in "\n".join(failure_lines(current))

"""Residual diagnosis: finds the effect a model lacks, and invents none where there is none."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, fields

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import signal as sps
from scipy import stats

from pytest_hevval.core.residual import (
    Candidate,
    CandidateFinding,
    Diagnosis,
    diagnose_residual,
    ljung_box,
)
from pytest_hevval.errors import DegenerateSignalError, SpecError
from pytest_hevval.report.diagnosis_text import note_text, summary
from pytest_hevval.results.codec import plain_json

DT = 0.01
NO_EFFECT = "no significant effect found"

Array = npt.NDArray[np.float64]


def ar1(rng: np.random.Generator, n: int, phi: float, sd: float = 1.0) -> Array:
    """x_t = φ x_{t−1} + ε_t, started at zero (φ = 1 gives a random walk)."""
    out: Array = sps.lfilter([1.0], [1.0, -phi], rng.standard_normal(n) * sd)
    return out


def smooth_channel(rng: np.random.Generator, n: int, tau_s: float) -> Array:
    """Unit-variance low-pass noise with time constant tau_s: a plausible measured channel."""
    a = math.exp(-DT / tau_s)
    x = sps.lfilter([1 - a], [1, -a], sps.lfilter([1 - a], [1, -a], rng.standard_normal(n)))
    out: Array = (x - x.mean()) / x.std()
    return out


def drive_cycle(n: int, delay_s: float = 0.0) -> Array:
    t = np.arange(n) * DT - delay_s
    out: Array = 10.0 * np.sin(2 * np.pi * 0.1 * t) + 3.0 * np.sin(2 * np.pi * 0.37 * t + 1.0)
    return out


def distractors(rng: np.random.Generator, n: int, count: int = 8) -> list[Candidate]:
    return [
        Candidate(f"other{j}", "channel", smooth_channel(rng, n, rng.uniform(0.5, 5.0)))
        for j in range(count)
    ]


def finding(diagnosis: Diagnosis, name: str) -> CandidateFinding:
    return next(f for f in diagnosis.candidates if f.name == name)


def anything_flagged(d: Diagnosis) -> bool:
    return (
        d.timing_significant
        or d.gain_significant
        or d.offset_significant
        or any(f.significant and f.selected for f in d.candidates)
    )


# --------------------------------------------------------------------------------------------
# (a)–(f): each kind of missing effect is found
# --------------------------------------------------------------------------------------------


def test_unused_channel_is_found_ranked_first_with_its_coefficient() -> None:
    rng = np.random.default_rng(11)
    n = 6000
    sim = drive_cycle(n)
    elevation = 2.0 * smooth_channel(rng, n, 2.0)
    ref = sim + 0.7 * elevation + ar1(rng, n, 0.9, 0.05)
    d = diagnose_residual(
        ref,
        sim,
        dt=DT,
        candidates=[*distractors(rng, n), Candidate("elevation", "channel", elevation)],
    )
    top = d.candidates[0]
    assert top.name == "elevation"
    assert top.rank == 1
    assert top.selected
    assert top.significant
    assert top.interval[0] <= 0.7 <= top.interval[1]
    assert top.interval[1] - top.interval[0] < 0.1
    assert top.explained_fraction > 0.9
    assert summary(d).startswith("elevation explains")
    assert not any(f.selected for f in d.candidates[1:] if f.kind == "channel")


def test_derivative_of_a_channel_is_preferred_over_the_channel() -> None:
    rng = np.random.default_rng(12)
    n = 6000
    sim = drive_cycle(n)
    elevation = smooth_channel(rng, n, 2.0)
    slope = np.gradient(elevation, DT)
    ref = sim + 0.3 * slope + ar1(rng, n, 0.9, 0.05)
    d = diagnose_residual(
        ref,
        sim,
        dt=DT,
        candidates=[
            Candidate("elevation", "channel", elevation),
            Candidate("d/dt elevation", "derivative", slope),
            *distractors(rng, n),
        ],
    )
    top = d.candidates[0]
    assert (top.name, top.kind) == ("d/dt elevation", "derivative")
    assert top.interval[0] <= 0.3 <= top.interval[1]
    assert not finding(d, "elevation").selected


def test_delayed_simulation_is_a_timing_error() -> None:
    rng = np.random.default_rng(13)
    n = 6000
    ref = drive_cycle(n) + ar1(rng, n, 0.9, 0.05)
    sim = drive_cycle(n, delay_s=0.5)
    d = diagnose_residual(ref, sim, dt=DT, candidates=distractors(rng, n))
    assert d.lag_s == pytest.approx(-0.5, abs=DT)
    assert d.timing_significant
    lag = d.candidates[0]
    assert lag.kind == "lag"
    # The lag coefficient is the delay in seconds (positive: the simulation is late).
    assert lag.interval[0] <= 0.5 <= lag.interval[1]
    assert not d.gain_significant
    assert not d.offset_significant
    assert "lags the reference by 0.5 s" in summary(d)


def test_a_delay_longer_than_the_signal_time_scale_is_explained_exactly() -> None:
    # 0.667 s delay on a 2.1 s period: far outside the first-order (derivative) regime.
    n = 500
    t = np.arange(n) * DT
    d = diagnose_residual(np.sin(3 * t), np.sin(3 * t - 2.0), dt=DT)
    assert d.lag_s == pytest.approx(-2.0 / 3.0, abs=2 * DT)
    assert d.timing_significant
    lag = d.candidates[0]
    assert lag.kind == "lag"
    assert lag.explained_fraction > 0.99
    assert lag.coefficient == pytest.approx(2.0 / 3.0, abs=2 * DT)


def test_gain_error_of_three_percent() -> None:
    rng = np.random.default_rng(14)
    n = 6000
    sim = drive_cycle(n) + 20.0
    ref = 1.03 * sim + ar1(rng, n, 0.9, 0.05)
    d = diagnose_residual(ref, sim, dt=DT, candidates=distractors(rng, n))
    assert d.gain_significant
    assert d.gain_interval[0] <= 1.03 <= d.gain_interval[1]
    assert not d.timing_significant
    # ref = 1.03 sim means no offset, although the mean residual is 0.6.
    assert not d.offset_significant
    assert d.offset_interval[0] <= 0.0 <= d.offset_interval[1]
    gain = d.candidates[0]
    assert gain.kind == "gain"
    assert gain.selected
    assert gain.interval[0] <= 0.03 <= gain.interval[1]
    assert "gain error +3.0 %" in summary(d)


def test_offset() -> None:
    rng = np.random.default_rng(15)
    n = 6000
    sim = drive_cycle(n)
    ref = sim + 0.5 + ar1(rng, n, 0.9, 0.05)
    d = diagnose_residual(ref, sim, dt=DT, candidates=distractors(rng, n))
    assert d.offset_significant
    assert d.offset_interval[0] <= 0.5 <= d.offset_interval[1]
    assert not d.gain_significant
    top = d.candidates[0]
    assert (top.kind, top.selected, top.significant) == ("offset", True, True)
    assert top.explained_fraction > 0.8
    assert summary(d).startswith("offset +0.5")


def test_two_effects_are_both_found_and_explain_more_together() -> None:
    rng = np.random.default_rng(16)
    n = 6000
    sim = drive_cycle(n)
    elevation = smooth_channel(rng, n, 2.0)
    wind = smooth_channel(rng, n, 0.7)
    ref = sim + 0.7 * elevation + 0.4 * wind + ar1(rng, n, 0.9, 0.05)
    d = diagnose_residual(
        ref,
        sim,
        dt=DT,
        candidates=[
            Candidate("elevation", "channel", elevation),
            Candidate("wind", "channel", wind),
            *distractors(rng, n),
        ],
    )
    first, second = d.candidates[0], d.candidates[1]
    assert {first.name, second.name} == {"elevation", "wind"}
    assert first.selected
    assert second.selected
    assert finding(d, "elevation").interval[0] <= 0.7 <= finding(d, "elevation").interval[1]
    assert finding(d, "wind").interval[0] <= 0.4 <= finding(d, "wind").interval[1]
    assert second.joint_explained_fraction is not None
    assert second.joint_explained_fraction > first.explained_fraction
    assert second.joint_explained_fraction > second.explained_fraction
    assert d.explained_fraction == pytest.approx(second.joint_explained_fraction)
    assert d.explained_fraction > 0.95
    assert "elevation explains" in summary(d)
    assert "wind explains" in summary(d)


def test_a_declared_candidate_with_a_constant_is_still_found_after_decimation() -> None:
    rng = np.random.default_rng(17)
    n = 60_000
    sim = drive_cycle(n)
    grade = smooth_channel(rng, n, 5.0) + 3.0
    ref = sim + 0.7 * (grade - 3.0) + ar1(rng, n, 0.99, 0.02)
    d = diagnose_residual(
        ref,
        sim,
        dt=DT,
        candidates=[Candidate("grade", "declared", grade), *distractors(rng, n, 4)],
        max_samples=5000,
    )
    top = d.candidates[0]
    assert top.name == "grade"
    assert top.interval[0] <= 0.7 <= top.interval[1]
    assert any("block means of 12 samples" in note_text(note) for note in d.notes)


# --------------------------------------------------------------------------------------------
# (g): controls — no effect, no finding
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("phi", [0.0, 0.9])
def test_noise_alone_is_reported_as_noise(phi: float) -> None:
    flagged = 0
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        n = 4000
        sim = drive_cycle(n)
        ref = sim + ar1(rng, n, phi, 0.05)
        d = diagnose_residual(ref, sim, dt=DT, candidates=distractors(rng, n, 10))
        if anything_flagged(d):
            flagged += 1
        else:
            assert summary(d).startswith(NO_EFFECT)
            assert d.explained_fraction == 0.0
            assert not any(f.selected for f in d.candidates)
    # Every test in the diagnosis runs at alpha = 5 %, family-wise; 3 of 10 would be a
    # false-positive rate no user could live with.
    assert flagged <= 2


def test_white_noise_is_white_and_ar_noise_is_not() -> None:
    rng = np.random.default_rng(5)
    n = 4000
    sim = drive_cycle(n)
    white = diagnose_residual(sim + 0.05 * rng.standard_normal(n), sim, dt=DT)
    coloured = diagnose_residual(sim + ar1(rng, n, 0.9, 0.05), sim, dt=DT)
    assert white.remaining.white
    assert summary(white) == (
        "no significant effect found: the residual is indistinguishable from noise"
    )
    assert not coloured.remaining.white
    assert summary(coloured).startswith(NO_EFFECT)
    assert white.effective_samples > 0.8 * n
    # AR(1) with φ = 0.9: n (1 − φ) / (1 + φ) ≈ n / 19.
    assert coloured.effective_samples == pytest.approx(n / 19, rel=0.5)


def _naive_ols_flags(r: Array, channels: list[Candidate], alpha: float) -> bool:
    """Plain OLS t-tests (iid errors), Bonferroni over the channels: the textbook mistake."""
    n = r.shape[0]
    for c in channels:
        x = np.column_stack([np.ones(n), c.values])
        beta, *_ = np.linalg.lstsq(x, r, rcond=None)
        e = r - x @ beta
        cov = np.linalg.inv(x.T @ x) * float(e @ e) / (n - 2)
        p = 2 * stats.t.sf(abs(beta[1]) / math.sqrt(cov[1, 1]), n - 2)
        if p < alpha / len(channels):
            return True
    return False


@pytest.mark.parametrize("phi", [0.95, 0.99])
def test_false_positive_rate_under_strongly_autocorrelated_residuals(phi: float) -> None:
    trials, hevval_hits, naive_hits = 40, 0, 0
    for seed in range(trials):
        rng = np.random.default_rng(1000 * int(phi * 100) + seed)
        n = 2000
        sim = drive_cycle(n)
        ref = sim + ar1(rng, n, phi, 0.05)
        channels = [
            # Half AR(1) with random persistence, half random walks: unrelated to the residual.
            Candidate(f"c{j}", "channel", ar1(rng, n, rng.uniform(0.9, 0.999) if j % 2 else 1.0))
            for j in range(20)
        ]
        d = diagnose_residual(ref, sim, dt=DT, candidates=channels)
        hevval_hits += any(f.significant for f in d.candidates if f.kind == "channel")
        naive_hits += _naive_ols_flags(ref - sim, channels, 0.05)
    assert hevval_hits <= 4  # ≤ 10 % of trials, for a nominal 5 %
    assert naive_hits >= 30  # plain OLS calls most of these unrelated channels significant


def test_offset_and_gain_tests_keep_their_size_near_a_unit_root() -> None:
    # AR(0.99) noise over 20 s leaves about ten independent samples: the offset is barely
    # identified. Without the bias correction of the AR fit and the effective degrees of
    # freedom the 5 % test rejects about twice as often as it should.
    rejected, flagged = 0, 0
    for seed in range(80):
        rng = np.random.default_rng(500 + seed)
        n = 2000
        sim = drive_cycle(n) + 20.0
        d = diagnose_residual(sim + ar1(rng, n, 0.99, 0.05), sim, dt=DT, max_lag_s=0.0)
        rejected += finding(d, "offset").p_value < 0.05
        flagged += d.gain_significant or d.offset_significant
    assert rejected <= 5
    assert flagged <= 4


def test_max_selected_and_alpha_limit_the_selection() -> None:
    rng = np.random.default_rng(22)
    n = 4000
    sim = drive_cycle(n)
    a, b = smooth_channel(rng, n, 2.0), smooth_channel(rng, n, 0.7)
    ref = sim + 0.7 * a + 0.4 * b + ar1(rng, n, 0.9, 0.05)
    cands = [Candidate("a", "channel", a), Candidate("b", "channel", b)]
    both = diagnose_residual(ref, sim, dt=DT, candidates=cands)
    one = diagnose_residual(ref, sim, dt=DT, candidates=cands, max_selected=1)
    none = diagnose_residual(ref, sim, dt=DT, candidates=cands, max_selected=0)
    assert [f.name for f in both.candidates if f.selected] == ["a", "b"]
    assert [f.name for f in one.candidates if f.selected] == ["a"]
    assert not any(f.selected for f in none.candidates)
    assert one.explained_fraction < both.explained_fraction
    # Not selected: b is reported alone, its interval widened by the unexplained 0.7 a.
    b_alone = finding(one, "b")
    assert b_alone.joint_explained_fraction is None
    assert b_alone.interval[0] <= 0.4 <= b_alone.interval[1]


def test_frequencies_are_in_hertz_of_the_original_rate_after_decimation() -> None:
    rng = np.random.default_rng(23)
    n = 40_000
    sim = drive_cycle(n)
    t = np.arange(n) * DT
    ref = sim + 0.3 * np.sin(2 * np.pi * 7.0 * t) + 0.02 * rng.standard_normal(n)
    d = diagnose_residual(ref, sim, dt=DT, max_samples=2000)
    # 7 Hz is above the Nyquist frequency of the 5 Hz regression grid, not of the record.
    assert d.dominant_frequencies_hz[0] == pytest.approx(7.0, abs=0.05)


# --------------------------------------------------------------------------------------------
# Property: an injected coefficient is recovered inside its interval
# --------------------------------------------------------------------------------------------


def test_injected_coefficient_is_covered_by_its_interval() -> None:
    covered: list[bool] = []

    @settings(
        derandomize=True,
        max_examples=25,
        deadline=None,
        suppress_health_check=[HealthCheck.too_slow],
    )
    @given(
        coef=st.floats(min_value=-1.5, max_value=1.5).filter(lambda c: abs(c) >= 0.1),
        seed=st.integers(min_value=0, max_value=2**32 - 1),
    )
    def one_draw(coef: float, seed: int) -> None:
        rng = np.random.default_rng(seed)
        n = 3000
        sim = drive_cycle(n)
        channel = smooth_channel(rng, n, 1.0)
        ref = sim + coef * channel + ar1(rng, n, 0.9, 0.05)
        d = diagnose_residual(
            ref,
            sim,
            dt=DT,
            candidates=[Candidate("x", "channel", channel), *distractors(rng, n, 3)],
        )
        found = finding(d, "x")
        assert found.selected
        assert found.rank == 1
        half = (found.interval[1] - found.interval[0]) / 2
        # Always close; inside the 95 % interval most of the time.
        assert abs(found.coefficient - coef) < 4 * half
        covered.append(found.interval[0] <= coef <= found.interval[1])

    one_draw()
    assert len(covered) >= 20
    assert sum(covered) >= 0.8 * len(covered)


# --------------------------------------------------------------------------------------------
# Pieces: Ljung-Box, spectrum, candidates housekeeping, exact match, JSON
# --------------------------------------------------------------------------------------------


def test_ljung_box_matches_its_formula() -> None:
    rng = np.random.default_rng(7)
    x = ar1(rng, 500, 0.3)
    result = ljung_box(x, (5, 10))
    n = x.shape[0]
    c = x - x.mean()
    rho = np.array([c[k:] @ c[:-k] for k in range(1, 11)]) / (c @ c)
    q = [n * (n + 2) * np.sum(rho[:h] ** 2 / (n - np.arange(1, h + 1))) for h in (5, 10)]
    p = [stats.chi2.sf(qh, h) for qh, h in zip(q, (5, 10), strict=True)]
    best = int(np.argmin(p))
    assert result.lags == (5, 10)
    assert result.statistic == pytest.approx(q[best], rel=1e-9)
    assert result.p_value == pytest.approx(min(1.0, 2 * p[best]), rel=1e-9)
    assert not result.white


def test_ljung_box_against_statsmodels() -> None:
    diagnostic = pytest.importorskip("statsmodels.stats.diagnostic")
    rng = np.random.default_rng(8)
    x = ar1(rng, 800, 0.1)
    ours = ljung_box(x, (10,))
    theirs = diagnostic.acorr_ljungbox(x, lags=[10])
    assert ours.statistic == pytest.approx(float(theirs["lb_stat"].iloc[0]), rel=1e-9)
    assert ours.p_value == pytest.approx(float(theirs["lb_pvalue"].iloc[0]), rel=1e-9)


def test_ljung_box_keeps_its_size_on_white_noise() -> None:
    rejections = sum(
        not ljung_box(np.random.default_rng(s).standard_normal(400), (10, 20)).white
        for s in range(200)
    )
    assert rejections <= 20


def test_dominant_frequency_of_an_unexplained_oscillation() -> None:
    rng = np.random.default_rng(9)
    n = 8000
    sim = drive_cycle(n)
    t = np.arange(n) * DT
    ref = sim + 0.3 * np.sin(2 * np.pi * 2.0 * t) + 0.02 * rng.standard_normal(n)
    d = diagnose_residual(ref, sim, dt=DT)
    assert d.dominant_frequencies_hz[0] == pytest.approx(2.0, abs=0.05)
    assert len(d.dominant_frequencies_hz) <= 3
    assert not d.remaining.white
    assert d.remaining.lags == (10, 20)


def test_explained_oscillation_leaves_a_white_remainder() -> None:
    rng = np.random.default_rng(10)
    n = 8000
    sim = drive_cycle(n)
    t = np.arange(n) * DT
    wobble = np.sin(2 * np.pi * 2.0 * t)
    ref = sim + 0.3 * wobble + 0.02 * rng.standard_normal(n)
    d = diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("wobble", "declared", wobble)])
    assert d.candidates[0].name == "wobble"
    assert d.remaining.white
    assert d.explained_fraction > 0.98


def test_constant_and_collinear_candidates_are_dropped_with_a_note() -> None:
    rng = np.random.default_rng(18)
    n = 3000
    sim = drive_cycle(n)
    elevation = smooth_channel(rng, n, 2.0)
    ref = sim + 0.7 * elevation + 0.05 * rng.standard_normal(n)
    d = diagnose_residual(
        ref,
        sim,
        dt=DT,
        candidates=[
            Candidate("elevation", "channel", elevation),
            Candidate("flat", "channel", np.full(n, 4.2)),
            Candidate("elevation in cm", "channel", 100.0 * elevation + 1.0),
        ],
    )
    names = [f.name for f in d.candidates]
    assert "flat" not in names
    assert "elevation in cm" not in names
    assert any("'flat' is constant" in note_text(note) for note in d.notes)
    # The same channel in another unit measures the same thing: one effect, named by the
    # first, the other listed as its member.
    assert d.candidates[0].name == "elevation"
    assert d.relevant[0].name == "elevation"
    assert d.relevant[0].members == ("elevation in cm",)


def test_exact_match() -> None:
    sim = drive_cycle(500)
    d = diagnose_residual(sim.copy(), sim, dt=DT)
    assert summary(d) == "the model matches the reference exactly: the residual is zero"
    assert d.candidates == ()
    assert not d.timing_significant
    assert not d.gain_significant
    assert not d.offset_significant


def test_constant_simulation_has_no_lag_and_no_gain() -> None:
    rng = np.random.default_rng(24)
    n = 1000
    sim = np.full(n, 3.0)
    d = diagnose_residual(3.5 + 0.05 * rng.standard_normal(n), sim, dt=DT)
    assert d.lag_s == 0.0
    assert (d.gain, d.gain_significant) == (1.0, False)
    assert d.offset_significant
    assert d.offset_interval[0] <= 0.5 <= d.offset_interval[1]
    assert any("simulated signal is constant" in note_text(note) for note in d.notes)
    assert [f.kind for f in d.candidates] == ["offset"]


@pytest.mark.parametrize(
    ("signal_scale", "channel_scale"), [(1e150, 1.0), (1e-150, 1e100), (3.7, 0.01)]
)
def test_results_do_not_depend_on_units(signal_scale: float, channel_scale: float) -> None:
    rng = np.random.default_rng(25)
    n = 2000
    sim = drive_cycle(n)
    channel = smooth_channel(rng, n, 2.0)
    ref = sim + 0.5 + 0.3 * channel + ar1(rng, n, 0.9, 0.05)
    base = diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("c", "channel", channel)])
    scaled = diagnose_residual(
        signal_scale * ref,
        signal_scale * sim,
        dt=DT,
        candidates=[Candidate("c", "channel", channel_scale * channel)],
    )
    assert [e.name for e in scaled.relevant] == [e.name for e in base.relevant]
    for e0, e1 in zip(base.effects, scaled.effects, strict=True):
        assert e1.share == pytest.approx(e0.share, rel=1e-9, abs=1e-12)
    assert scaled.gain == pytest.approx(base.gain, rel=1e-9)
    assert scaled.offset / signal_scale == pytest.approx(base.offset, rel=1e-9)
    c0, c1 = finding(base, "c"), finding(scaled, "c")
    assert c1.coefficient * channel_scale / signal_scale == pytest.approx(c0.coefficient, rel=1e-9)
    assert c1.p_value == pytest.approx(c0.p_value, rel=1e-6, abs=1e-300)
    assert c1.explained_fraction == pytest.approx(c0.explained_fraction, rel=1e-9)


def test_as_dict_is_json_and_mirrors_the_fields() -> None:
    rng = np.random.default_rng(19)
    n = 2000
    sim = drive_cycle(n)
    elevation = smooth_channel(rng, n, 2.0)
    d = diagnose_residual(
        sim + elevation + 0.05 * rng.standard_normal(n),
        sim,
        dt=DT,
        candidates=[Candidate("elevation", "channel", elevation)],
    )
    payload = plain_json(asdict(d))
    text = json.dumps(payload, allow_nan=False)
    assert json.loads(text) == payload
    assert set(payload) == {f.name for f in fields(Diagnosis)}
    first = payload["candidates"][0]
    assert set(first) == {
        "name",
        "kind",
        "explained_fraction",
        "joint_explained_fraction",
        "coefficient",
        "interval",
        "p_value",
        "significant",
        "selected",
        "rank",
    }
    assert set(payload["remaining"]) == {"lags", "statistic", "p_value", "white"}
    assert first["name"] == "elevation"
    assert first["rank"] == 1


def test_user_candidate_named_like_an_automatic_one_is_kept() -> None:
    rng = np.random.default_rng(20)
    n = 2000
    sim = drive_cycle(n)
    lag = smooth_channel(rng, n, 1.0)
    d = diagnose_residual(
        sim + 0.5 * lag + 0.05 * rng.standard_normal(n),
        sim,
        dt=DT,
        candidates=[Candidate("lag", "channel", lag)],
    )
    assert (d.candidates[0].name, d.candidates[0].kind) == ("lag", "channel")
    assert {f.name for f in d.candidates} >= {"lag", "lag (automatic)", "gain"}


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("reference", "simulated", "dt", "message"),
    [
        (np.r_[np.ones(20), np.nan], np.ones(21), DT, "reference contains 1 NaN"),
        (np.ones(21), np.r_[np.ones(20), np.inf], DT, "simulated contains 1 NaN or infinite"),
        (np.ones(20), np.ones(21), DT, "reference has 20 samples but simulated has 21"),
        (np.ones(9), np.zeros(9), DT, "at least 10 samples"),
        (np.ones(20), np.zeros(20), 0.0, "dt must be a positive"),
        (np.ones(20), np.zeros(20), -0.1, "dt must be a positive"),
        (np.ones(20), np.zeros(20), math.nan, "dt must be a positive"),
        (np.ones((4, 5)), np.ones((4, 5)), DT, "one-dimensional"),
    ],
)
def test_degenerate_input(reference: Array, simulated: Array, dt: float, message: str) -> None:
    with pytest.raises(DegenerateSignalError, match=message):
        diagnose_residual(reference, simulated, dt=dt)


def test_bad_candidates_and_options() -> None:
    sim = drive_cycle(100)
    ref = sim + 1.0
    with pytest.raises(DegenerateSignalError, match="candidate 'x' has 99 samples"):
        diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("x", "channel", np.ones(99))])
    bad = np.r_[np.ones(99), np.nan]
    with pytest.raises(DegenerateSignalError, match="candidate 'x' contains 1 NaN"):
        diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("x", "channel", bad)])
    twice = [Candidate("x", "channel", sim), Candidate("x", "declared", sim)]
    with pytest.raises(SpecError, match="'x' is used twice"):
        diagnose_residual(ref, sim, dt=DT, candidates=twice)
    with pytest.raises(SpecError, match="has kind 'speed'"):
        diagnose_residual(ref, sim, dt=DT, candidates=[Candidate("x", "speed", sim)])  # type: ignore[arg-type]
    with pytest.raises(SpecError, match="alpha"):
        diagnose_residual(ref, sim, dt=DT, alpha=1.0)
    with pytest.raises(SpecError, match="max_samples"):
        diagnose_residual(ref, sim, dt=DT, max_samples=5)
    with pytest.raises(SpecError, match="max_selected must lie between 0 and 11, got 12"):
        diagnose_residual(ref, sim, dt=DT, max_selected=12)
    assert diagnose_residual(ref, sim, dt=DT, max_selected=11).effects

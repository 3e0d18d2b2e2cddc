"""The diagnosis's own statistics (``core/stats.py``) against the field's libraries.

statsmodels and arch are test dependencies only: the package computes these numbers itself, in
numpy, and these tests show that it computes the same ones, on the series that break naive
implementations (persistent up to a random walk, oscillating, trending, heavy-tailed; the
shared :func:`tests.strategies.time_series`), from 200 to 100 000 samples. Where the project's
method differs from the library's default on purpose, the test states the option that makes
them agree and ``docs/diagnosis.md`` says why.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy import signal as sps
from scipy import stats as scipy_stats

from pytest_hevval.core import stats as stats_module
from pytest_hevval.core.stats import (
    andrews_bandwidth,
    ar_fit,
    ar_model_fit,
    ar_model_screen,
    ar_order,
    ar_spectrum,
    effective_samples,
    hac_fit,
    ljung_box,
    politis_white,
)
from pytest_hevval.core.uncertainty import resample_counts

from .strategies import SERIES_KINDS, time_series, time_series_of

statsmodels_api = pytest.importorskip("statsmodels.api")
ar_model = pytest.importorskip("statsmodels.tsa.ar_model")
diagnostic = pytest.importorskip("statsmodels.stats.diagnostic")
arima_process = pytest.importorskip("statsmodels.tsa.arima_process")
arch_bootstrap = pytest.importorskip("arch.bootstrap")

#: Long series are checked on a few cases only, each vectorised, so the file stays fast.
LONG = 100_000

reference = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _kendall_corrected(params: np.ndarray, m: int) -> np.ndarray:
    """statsmodels' least-squares AR coefficients with the project's documented bias
    correction added to φ₁ (Kendall 1954): Σφ + (1 + 3Σφ)/m, at most 1 − 1/m."""
    phi = np.array(params, dtype=np.float64)
    persistence = float(np.sum(phi))
    if persistence > 0.0:
        phi[0] += min(persistence + (1.0 + 3.0 * persistence) / m, 1.0 - 1.0 / m) - persistence
    return phi


def _whitened(x: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """x_t − Σ φ_i x_{t−i}, t ≥ p, by scipy's filter (the project has its own loop)."""
    filtered = sps.lfilter(np.concatenate(([1.0], -phi)), [1.0], x, axis=0)
    return np.asarray(filtered[phi.shape[0] :], dtype=np.float64)


def _statsmodels_hac(y: np.ndarray, x: np.ndarray, phi: np.ndarray):  # type: ignore[no-untyped-def]
    """statsmodels' OLS on the series filtered by φ, with a Newey–West covariance using the
    project's kernel: Bartlett weights 1 − l/S_T at the Andrews bandwidth S_T (a real number;
    statsmodels' own Bartlett uses 1 − l/(L + 1) for an integer L), lags up to ⌈S_T⌉, and the
    small-sample factor n/(n − k)."""
    ys, xs = _whitened(y, phi), _whitened(x, phi)
    plain = statsmodels_api.OLS(ys, xs).fit()
    bandwidth = andrews_bandwidth(xs * plain.resid[:, None])
    lags = min(ys.shape[0] - 1, math.ceil(bandwidth))

    def kernel(nlags: int) -> np.ndarray:
        return np.clip(1.0 - np.arange(nlags + 1) / max(bandwidth, 1.0), 0.0, None)

    return statsmodels_api.OLS(ys, xs).fit(
        cov_type="HAC", cov_kwds={"maxlags": lags, "kernel": kernel, "use_correction": True}
    )


@reference
@given(residual=time_series(), regressor=time_series(), seed=st.integers(0, 2**32 - 1))
def test_hac_fit_is_statsmodels_newey_west_on_the_filtered_data(
    residual: np.ndarray, regressor: np.ndarray, seed: int
) -> None:
    n = min(residual.shape[0], regressor.shape[0])
    x = np.column_stack([np.ones(n), regressor[:n]])
    y = 0.3 * x[:, 1] + residual[:n]
    fit = hac_fit(y, x, ar_order(residual[:n] - float(np.mean(residual[:n]))))
    expected = _statsmodels_hac(y, x, fit.phi)
    np.testing.assert_allclose(fit.beta, expected.params, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(fit.cov, expected.cov_params(), rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("kind", ["random_walk", "persistent", "oscillating"])
def test_hac_fit_is_statsmodels_newey_west_on_long_records(kind: str) -> None:
    """10⁵ samples: the random walk's filter reaches its cap (persistence 1 − 1/n), the case
    whose intercept the project once lost."""
    residual = time_series_of(kind, LONG, seed=9, parameter=0.9)
    regressor = time_series_of("oscillating", LONG, seed=10)
    x = np.column_stack([np.ones(LONG), regressor])
    fit = hac_fit(regressor + residual, x, 1)
    expected = _statsmodels_hac(regressor + residual, x, fit.phi)
    np.testing.assert_allclose(fit.beta, expected.params, rtol=1e-7)
    np.testing.assert_allclose(fit.cov, expected.cov_params(), rtol=1e-6)


def test_andrews_bandwidth_of_one_column_is_its_closed_form() -> None:
    """For one column, α(1) = 4ρ²/((1 − ρ)²(1 + ρ)²) (Andrews 1991, eq. 6.4)."""
    scores = time_series_of("persistent", 5000, seed=4, parameter=0.0)[:, None]
    rho = float(scores[1:, 0] @ scores[:-1, 0] / (scores[:-1, 0] @ scores[:-1, 0]))
    alpha = 4.0 * rho**2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    assert andrews_bandwidth(scores) == pytest.approx(1.1447 * (alpha * 5000) ** (1 / 3))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(series=time_series())
def test_ar_order_is_statsmodels_bic_choice(series: np.ndarray) -> None:
    """BIC over orders 0 … min(10, n/10 − 1), every order fitted on the same samples: the
    project's nested Cholesky solve picks what ``ar_select_order(glob=False)`` picks."""
    u = series - float(np.mean(series))
    top = min(10, series.shape[0] // 10 - 1)
    chosen = ar_model.ar_select_order(u, maxlag=top, ic="bic", trend="n", glob=False)
    assert ar_order(u) == len(chosen.ar_lags or [])


@reference
@given(series=time_series(), order=st.integers(1, 10))
def test_ar_fit_is_statsmodels_autoreg_plus_the_bias_correction(
    series: np.ndarray, order: int
) -> None:
    u = series - float(np.mean(series))
    params = ar_model.AutoReg(u, order, trend="n").fit().params
    expected = _kendall_corrected(params, u.shape[0] - order)
    np.testing.assert_allclose(ar_fit(u, order), expected, rtol=1e-7, atol=1e-9)


def test_ar_fit_is_statsmodels_autoreg_on_long_records() -> None:
    for kind in SERIES_KINDS:
        u = time_series_of(kind, LONG, seed=2)
        u = u - float(np.mean(u))
        params = ar_model.AutoReg(u, 2, trend="n").fit().params
        expected = _kendall_corrected(params, LONG - 2)
        np.testing.assert_allclose(ar_fit(u, 2), expected, rtol=1e-7, atol=1e-9, err_msg=kind)


@reference
@given(series=time_series())
def test_ljung_box_is_statsmodels_with_a_bonferroni_minimum(series: np.ndarray) -> None:
    """Q(h) and its χ² p-value are statsmodels' at every lag; the project reports the lag of
    the smallest p-value, that p-value times the number of lags."""
    lags = [10, 20]
    table = diagnostic.acorr_ljungbox(series, lags=lags)
    found = ljung_box(series, lags)
    best = int(np.argmin(table["lb_pvalue"].to_numpy()))
    assert found.statistic == pytest.approx(float(table["lb_stat"].iloc[best]), rel=1e-9)
    assert found.p_value == pytest.approx(
        min(1.0, 2.0 * float(table["lb_pvalue"].iloc[best])), rel=1e-6, abs=1e-300
    )


@reference
@given(series=time_series(min_size=50, max_size=5000))
def test_politis_white_block_length_is_arch(series: np.ndarray) -> None:
    expected = arch_bootstrap.optimal_block_length(series).to_numpy()[0]
    found = politis_white(series)
    np.testing.assert_allclose([found.stationary, found.circular], expected, rtol=1e-9)


@pytest.mark.parametrize("kind", ["random_walk", "oscillating"])
def test_politis_white_block_length_is_arch_on_long_records(kind: str) -> None:
    """(arch's loop over lags takes seconds at 10⁵ samples where BLAS threads compete for the
    cores; the project's FFT takes a tenth of a second, so two kinds are checked here and the
    rest by ``benchmarks/bench_stats_reference.py``.)"""
    series = time_series_of(kind, LONG, seed=5)
    expected = arch_bootstrap.optimal_block_length(series).to_numpy()[0]
    found = politis_white(series)
    np.testing.assert_allclose([found.stationary, found.circular], expected, rtol=1e-9)


@pytest.mark.parametrize("kind", ["persistent", "oscillating", "heavy_tailed"])
def test_non_overlapping_block_bootstrap_agrees_with_arch_moving_blocks(kind: str) -> None:
    """The λ intervals resample non-overlapping blocks (``resample_counts``); arch resamples
    moving (circular) blocks. At one block length both estimate the same variance of a mean:
    over 20 records their bootstrap standard errors agree within 3 % on average, each within
    the Monte Carlo and block-placement error of a single record (25 %)."""
    n, replicates = 4000, 500
    ratios = []
    for seed in range(20):
        series = time_series_of(kind, n, seed=seed, parameter=0.6)
        length = max(1, round(politis_white(series).circular))
        blocks = n // length
        sums = series[: blocks * length].reshape(blocks, length).sum(axis=1)
        counts = resample_counts(blocks, replicates, seed)
        ours = float(np.std(counts @ sums / (blocks * length), ddof=1))
        bootstrap = arch_bootstrap.CircularBlockBootstrap(
            length, series[: blocks * length], seed=seed
        )
        theirs = math.sqrt(float(bootstrap.var(np.mean, reps=replicates)[0]))
        ratios.append(ours / theirs)
    assert np.all(np.abs(np.log(ratios)) < math.log(1.25))
    assert abs(float(np.mean(ratios)) - 1.0) < 0.03


@pytest.mark.parametrize(
    ("ar", "shocks"),
    [
        ([0.99], "normal"),  # near a unit root
        ([0.9], "t3"),  # heavy-tailed
        ([2 * 0.9 * math.cos(0.5), -0.81], "normal"),  # oscillating: 1/10 of the truth before
        ([2 * 0.95 * math.cos(0.3), -0.9025], "normal"),  # oscillating: 1/20 of it before
    ],
)
def test_effective_samples_are_those_of_the_process(ar: list[float], shocks: str) -> None:
    """n γ₀ / Σ_k γ_k of the generating AR process (statsmodels' ``ArmaProcess``: its
    autocovariance γ₀ and long-run variance σ²/(1 − Σφ)²), within 15 % in the median of eight
    records of 20 000 samples. The former rule, bounded by the AR(1) value n(1 − ρ₁)/(1 + ρ₁),
    gave an oscillating residual a tenth to a twentieth of this."""
    process = arima_process.ArmaProcess(np.concatenate(([1.0], -np.asarray(ar))))
    n = 20_000
    truth = n * float(process.acovf(1)[0]) * (1.0 - sum(ar)) ** 2
    rng = np.random.default_rng(7)
    if shocks == "t3":
        innovations = rng.standard_t(3, size=(8, n + 1000)) / math.sqrt(3.0)
    else:
        innovations = rng.standard_normal((8, n + 1000))
    records = sps.lfilter([1.0], np.concatenate(([1.0], -np.asarray(ar))), innovations)
    found = [effective_samples(u, ar_order(u - float(np.mean(u)))) for u in records[:, 1000:]]
    assert float(np.median(found)) == pytest.approx(min(truth, n), rel=0.15)


@pytest.mark.parametrize(
    ("kind", "most"),
    [("random_walk", 10.0), ("trending", 20.0), ("slow_wave", 20.0)],
)
def test_a_drift_or_a_slow_wave_is_worth_few_samples(kind: str, most: float) -> None:
    """No AR process of ten lags describes these; their lowest frequencies say so, and the
    mean of such a record is known to within a few of its samples' worth whatever n is."""
    for n in (200, 20_000):
        for seed in range(3):
            if kind == "slow_wave":
                rng = np.random.default_rng(seed)
                u = np.sin(2 * np.pi * 3 * np.arange(n) / n) + 0.01 * rng.standard_normal(n)
            else:
                u = time_series_of(kind, n, seed, parameter=1.0)
                if kind == "trending":
                    u = u + 20.0 * np.linspace(0.0, 1.0, n)
            assert effective_samples(u, ar_order(u - float(np.mean(u)))) <= most, (n, seed)


def _ar_model_reference(y: np.ndarray, x: np.ndarray, order: int):  # type: ignore[no-untyped-def]
    """statsmodels' OLS, AutoReg on its residual (with the documented bias correction) and
    ``arma_acovf`` for that AR model's autocovariances, put together densely: the exact
    covariance (XᵀX)⁻¹ XᵀΣX (XᵀX)⁻¹ of OLS when the residual is that AR process."""
    n, k = x.shape
    plain = statsmodels_api.OLS(y, x).fit()
    u = plain.resid
    if order:
        params = ar_model.AutoReg(u, order, trend="n").fit().params
        phi = _kendall_corrected(params, n - order)
    else:
        phi = np.zeros(0)
    innovations = _whitened(u, phi)
    sigma2 = float(innovations @ innovations) / max(innovations.shape[0] - k, 1)
    gamma = arima_process.arma_acovf(np.concatenate(([1.0], -phi)), [1.0], nobs=n, sigma2=sigma2)
    lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    bread = np.linalg.inv(x.T @ x)
    return plain.params, bread @ (x.T @ gamma[lags] @ x) @ bread, phi


@reference
@given(residual=time_series(max_size=1200), regressor=time_series(max_size=1200))
def test_ar_model_fit_is_ols_with_its_ar_models_exact_covariance(
    residual: np.ndarray, regressor: np.ndarray
) -> None:
    """The sizes of the diagnosis: OLS, and its covariance under the AR model fitted to its
    residual, computed in the frequency domain; here against the dense n × n product. Where
    the residual's lowest frequencies hold more than the AR model allows (a drift), the
    spectrum is raised there, and the covariance can only grow."""
    n = min(residual.shape[0], regressor.shape[0])
    x = np.column_stack([np.ones(n), regressor[:n]])
    y = 0.3 * x[:, 1] + residual[:n]
    order = ar_order(residual[:n] - float(np.mean(residual[:n])))
    fit = ar_model_fit(y, x, order)
    # A residual that the regressor reproduces leaves only rounding to model.
    assume(float(np.std(y - x @ fit.beta)) > 1e-6 * float(np.std(y)))
    params, cov, phi = _ar_model_reference(y, x, order)
    np.testing.assert_allclose(fit.beta, params, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(fit.phi, phi, rtol=1e-7, atol=1e-9)
    u = y - x @ fit.beta
    size = stats_module._fft_size(n, fit.phi)
    raised = not np.array_equal(
        stats_module.residual_spectrum(u, fit.phi, 2, size),
        ar_spectrum(fit.phi, stats_module._innovations(u, fit.phi, 2), size),
    )
    if raised:
        assert np.all(np.diag(fit.cov) >= np.diag(cov) * (1.0 - 1e-9))
    else:
        np.testing.assert_allclose(fit.cov, cov, rtol=1e-6, atol=1e-12)


@reference
@given(residual=time_series(max_size=1500), seed=st.integers(0, 2**32 - 1))
def test_ar_model_screen_is_ar_model_fit_one_candidate_at_a_time(
    residual: np.ndarray, seed: int
) -> None:
    """Frisch–Waugh–Lovell: each candidate's coefficient and standard error in the screen are
    those of the full fit with the base and that candidate."""
    n = residual.shape[0]
    rng = np.random.default_rng(seed)
    base = np.column_stack([np.ones(n), np.cumsum(rng.standard_normal(n))])
    z_rows = np.stack([sps.lfilter([1.0], [1.0, -0.9], rng.standard_normal(n)) for _ in range(3)])
    y = base @ np.array([0.5, 0.1]) + 0.2 * z_rows[0] + residual
    order = ar_order(residual - float(np.mean(residual)))
    screened = ar_model_screen(y, base, z_rows, order)
    for j in range(3):
        x = np.column_stack([base, z_rows[j]])
        fit = ar_model_fit(y, x, order)
        # A residual that the design reproduces leaves only rounding to model.
        assume(float(np.std(y - x @ fit.beta)) > 1e-6 * float(np.std(y)))
        assert screened.beta[j] == pytest.approx(fit.beta[-1], rel=1e-6, abs=1e-9)
        assert screened.se[j] == pytest.approx(math.sqrt(fit.cov[-1, -1]), rel=1e-6)
        # The degrees of freedom count the residual's variance, whose lowest frequencies are
        # raised by a χ² check; rounding can tip a check that sits on its limit either way.
        if not _low_frequency_check_on_its_limit(y - x @ fit.beta, fit.phi):
            assert screened.df[j] == fit.df[-1]


def _low_frequency_check_on_its_limit(u: np.ndarray, phi: np.ndarray) -> bool:
    n = u.shape[0]
    size = stats_module._fft_size(n, phi)
    spectrum = ar_spectrum(phi, stats_module._innovations(u, phi, 3), size)
    lowest = min(stats_module.LOW_FREQUENCIES, (n - 1) // 2)
    periodogram = np.abs(np.fft.rfft(u - float(np.mean(u)))[1 : lowest + 1]) ** 2 / n
    at = np.rint(np.arange(1, lowest + 1) * size / n).astype(np.int64)
    statistic = float(np.sum(2.0 * periodogram / spectrum[at]))
    limit = float(scipy_stats.chi2.ppf(1.0 - stats_module.LOW_FREQUENCY_LEVEL, 2 * lowest))
    return abs(statistic - limit) <= 1e-3 * limit

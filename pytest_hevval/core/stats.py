"""Time-series statistics for regressions on autocorrelated residuals.

Feasible GLS: the data filtered by an AR model of the residual chosen by BIC (Cochrane–Orcutt),
then heteroscedasticity- and autocorrelation-consistent (Newey–West) covariances with the
Andrews plug-in bandwidth on the filtered regression; effective sample sizes and degrees of
freedom, the Ljung–Box test, Politis–White block lengths and the dominant frequencies of a
spectrum. Used by :mod:`pytest_hevval.core.residual`; pure numpy and scipy.
``tests/test_stats_reference.py`` checks each against statsmodels or arch.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import fft as sfft
from scipy import linalg as sla

FloatArray = npt.NDArray[np.float64]

#: Highest AR order tried by the pre-whitening filter (chosen by BIC).
MAX_AR_ORDER = 10
#: The AR(1) coefficient of the scores in the Andrews plug-in is bounded, as Andrews & Monahan
#: (1992) bound their pre-whitening filter's, so that the bandwidth stays finite when the
#: AR filter leaves a near-unit root.
RHO_CAP = 0.97
#: Relative singular-value cut-off of a design matrix whose columns were scaled to unit length:
#: a direction of X whose singular value is under this fraction of the largest is null. The
#: cut-off is decided on the singular values of X itself, never on those of XᵀX (their squares).
RCOND = 1e-10
#: The normal equations of a column-scaled design are solved directly while its Gram matrix's
#: smallest eigenvalue is at least this fraction of its largest (singular values of X within
#: 10⁴ of each other): the solution's relative error is then at most about ε·10⁸ ≈ 2·10⁻⁸. A
#: worse-conditioned design is solved through the SVD of X.
GRAM_CONDITION = 1e-8
#: The lowest Fourier frequencies whose periodogram checks an AR model's long-run variance in
#: :func:`effective_samples` (a drift or a slow wave puts its power there).
LOW_FREQUENCIES = 8
#: ... and the level at which that check rejects the AR model.
LOW_FREQUENCY_LEVEL = 1e-3
#: How many spectral peaks :func:`dominant_frequencies` reports.
N_PEAKS = 3


@dataclass(frozen=True)
class Whiteness:
    """Ljung-Box portmanteau test of the remaining residual.

    Attributes
    ----------
    lags:
        The lags h at which Q(h) was evaluated, in samples of the regression grid.
    statistic:
        Q(h) at the lag giving the smallest p-value.
    p_value:
        That smallest p-value, Bonferroni-adjusted over ``lags``.
    white:
        ``p_value >= alpha``: no autocorrelation detected.
    """

    lags: tuple[int, ...]
    statistic: float
    p_value: float
    white: bool


# Thread-parallel BLAS gains nothing on these memory-bound, thin products and, on a machine
# whose cores are already busy, its spinning threads slow them down by an order of magnitude;
# numpy's own einsum loops are single-threaded.


def dot(a: FloatArray, b: FloatArray) -> float:
    return float(np.einsum("t,t->", a, b))


def project_out(rows: FloatArray, q: FloatArray) -> FloatArray:
    """Each row minus its projection on the orthonormal columns of q."""
    coef = np.einsum("jt,tk->jk", rows, q)
    return np.asarray(rows - np.einsum("jk,tk->jt", coef, q), dtype=np.float64)


def block_means(x: FloatArray, factor: int) -> FloatArray:
    if factor == 1:
        return x
    blocks = x.shape[0] // factor
    means = x[: blocks * factor].reshape(blocks, factor).mean(axis=1)
    return np.asarray(means, dtype=np.float64)


def lag_matrix(u: FloatArray, order: int) -> FloatArray:
    """Columns u[t−1], …, u[t−order] for t = order … n−1."""
    n = u.shape[0]
    return np.column_stack([u[order - i : n - i] for i in range(1, order + 1)])


def varies(x: FloatArray) -> bool:
    """Whether x takes two different values. A constant series is caught before centring it:
    its mean's rounding would leave a constant non-zero remainder that looks like a signal."""
    return bool(x.shape[0]) and float(np.max(x)) > float(np.min(x))


def column_lengths(x: FloatArray) -> FloatArray:
    """The Euclidean length of every column of x; 1 for a zero column (it stays zero)."""
    norms = np.sqrt(np.einsum("ti,ti->i", x, x))
    return np.asarray(np.where(norms > 0.0, norms, 1.0), dtype=np.float64)


@dataclass(frozen=True)
class LeastSquares:
    """A least-squares fit y ≈ X β.

    Attributes
    ----------
    coef:
        β; one column per column of y when y is a matrix.
    inverse:
        (XᵀX)⁺ with the same directions left out as in β: the bread of a sandwich covariance.
    rank:
        How many directions of X were kept.
    """

    coef: FloatArray
    inverse: FloatArray
    rank: int


def least_squares(x: FloatArray, y: FloatArray) -> LeastSquares:
    """Least squares of y (a vector, or one series per column) on the columns of x.

    The columns are scaled to unit length first, so a column's units never decide whether it is
    kept: after pre-whitening by a filter whose persistence is 1 − 1/n, the constant column is
    10⁻⁵ high next to a regressor in watts, and it is exactly as identified. Directions whose
    singular value (of the scaled X, not of XᵀX) is under :data:`RCOND` of the largest are left
    out, and β is the shortest solution in the scaled coordinates.

    A design whose scaled Gram matrix is well conditioned (:data:`GRAM_CONDITION`), as all but
    nearly collinear ones are, is solved through that k × k matrix, one pass over the samples;
    any other through the SVD of X itself.
    """
    k = x.shape[1]
    if k == 0:
        return LeastSquares(coef=np.zeros((0, *y.shape[1:])), inverse=np.zeros((0, 0)), rank=0)
    norms = column_lengths(x)
    scale = np.outer(norms, norms)
    eigval, eigvec = np.linalg.eigh(np.einsum("ti,tj->ij", x, x) / scale)
    if eigval[-1] > 0.0 and eigval[0] >= GRAM_CONDITION * eigval[-1]:
        inverse = (eigvec / eigval) @ eigvec.T / scale
        coef = np.einsum("ij,j...->i...", inverse, np.einsum("tj,t...->j...", x, y))
        rank = k
    else:
        u, s, vt = np.linalg.svd(x / norms, full_matrices=False)
        keep = s > RCOND * max(float(s[0]), 1e-300)
        u, s, vt = u[:, keep], s[keep], vt[keep]
        inverse = (vt.T / s**2) @ vt / scale
        # Uᵀy, not Xᵀy: the normal equations would square the condition number.
        scaled = np.einsum("ji,j...->i...", vt / s[:, None], np.einsum("tj,t...->j...", u, y))
        coef = np.einsum("i,i...->i...", 1.0 / norms, scaled)
        rank = int(s.shape[0])
    return LeastSquares(
        coef=np.asarray(coef, dtype=np.float64),
        inverse=np.asarray(inverse, dtype=np.float64),
        rank=rank,
    )


def ar_order(u: FloatArray) -> int:
    """AR order by BIC (Schwarz 1978), all orders fitted on the same sample.

    One factorisation of the lag matrix gives every order's residual sum of squares, because
    the AR(p) regressors are the first p lag columns.
    """
    n = u.shape[0]
    top = min(MAX_AR_ORDER, max(0, n // 10 - 1))
    if top == 0:
        return 0
    y = u[top:]
    lagged = lag_matrix(u, top)
    total = dot(y, y)
    if total <= 0.0:
        return 0
    # Cholesky of the lag Gram matrix is the R of a QR of the lag matrix: the forward solve
    # gives the projections of y on the nested AR(1) … AR(top) regressor spaces.
    gram = np.einsum("ti,tj->ij", lagged, lagged)
    try:
        chol = np.linalg.cholesky(gram + np.eye(top) * 1e-12 * np.trace(gram))
    except np.linalg.LinAlgError:
        return 0
    proj = sla.solve_triangular(chol, np.einsum("ti,t->i", lagged, y), lower=True) ** 2
    ssr = np.maximum(total - np.concatenate(([0.0], np.cumsum(proj))), total * 1e-15)
    m = y.shape[0]
    bic = m * np.log(ssr / m) + np.arange(top + 1) * math.log(m)
    return int(np.argmin(bic))


def ar_fit(u: FloatArray, order: int) -> FloatArray:
    """Least-squares AR(order) coefficients φ of u (no intercept: u has mean zero).

    The persistence Σφ is biased low by about (1 + 3Σφ)/n (Kendall 1954, for AR(1)); that bias
    makes tests anti-conservative near a unit root, so it is added back to φ₁, keeping
    Σφ ≤ 1 − 1/n.
    """
    if order == 0 or u.shape[0] <= 2 * order + 2:
        return np.zeros(0)
    y = u[order:]
    if dot(y, y) == 0.0:
        return np.zeros(0)
    phi = np.array(least_squares(lag_matrix(u, order), y).coef, dtype=np.float64)
    persistence = float(np.sum(phi))
    if persistence > 0.0:
        # Σφ = 1 would null the constant column of the whitened design; 1 − 1/n keeps the
        # offset identified, with the huge variance a unit root implies.
        m = y.shape[0]
        corrected = min(persistence + (1.0 + 3.0 * persistence) / m, 1.0 - 1.0 / m)
        phi[0] += corrected - persistence
    return phi


def lag1_autocorrelation(x: FloatArray) -> FloatArray:
    """Lag-one autocorrelation of each column about its mean; 1 for a constant column."""
    centred = x - x.mean(axis=0)
    num = np.einsum("ij,ij->j", centred[1:], centred[:-1])
    den = np.einsum("ij,ij->j", centred, centred)
    scale = np.einsum("ij,ij->j", x, x)
    constant = den <= 1e-24 * np.maximum(scale, 1e-300)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(constant, 1.0, num / np.where(constant, 1.0, den))
    return np.asarray(np.clip(rho, -1.0, 1.0), dtype=np.float64)


def effective_df(n: int, k: int, phi: FloatArray, rho: FloatArray) -> npt.NDArray[np.int64]:
    """Degrees of freedom n (1 − φρ)/(1 + φρ) − k per regressor (Bretherton et al. 1999).

    φ is the persistence of the noise (Σφ of its AR model) and ρ the lag-one autocorrelation
    of the regressor: a slowly varying regressor in persistent noise offers few independent
    comparisons however many samples there are, and the estimated filter is least accurate
    exactly there.
    """
    persistence = float(np.clip(np.sum(phi), 0.0, 1.0)) if phi.shape[0] else 0.0
    prod = np.clip(persistence * rho, 0.0, 1.0)
    eff = n * (1.0 - prod) / (1.0 + prod) - k
    return np.asarray(np.clip(np.floor(eff), 1, max(n - k, 1)), dtype=np.int64)


def whiten(x: FloatArray, phi: FloatArray) -> FloatArray:
    """x_t − Σ φ_i x_{t−i} for t = p … n−1, on a vector or on every column of a matrix."""
    p = phi.shape[0]
    if p == 0:
        return x
    n = x.shape[0]
    out = np.array(x[p:], dtype=np.float64, copy=True)
    for i in range(1, p + 1):
        out -= phi[i - 1] * x[p - i : n - i]
    return out


def orthonormal(x: FloatArray) -> FloatArray:
    """Orthonormal basis of the column space of x, dropping the directions that
    :func:`least_squares` drops (columns scaled to unit length first)."""
    if x.shape[1] == 0:
        return x
    u, s, _ = np.linalg.svd(x / column_lengths(x), full_matrices=False)
    keep = s > RCOND * max(float(s[0]), 1e-300)
    return np.asarray(u[:, keep], dtype=np.float64)


def autocovariances(scores: FloatArray, max_lag: int) -> FloatArray:
    """Σ_t s_t s_{t−l} for l = 0 … max_lag, per column, by FFT."""
    n = scores.shape[0]
    size = sfft.next_fast_len(2 * n)
    spectrum = np.fft.rfft(scores, n=size, axis=0)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), n=size, axis=0)
    return np.asarray(acov[: max_lag + 1], dtype=np.float64)


def andrews_bandwidth(scores: FloatArray) -> float:
    """Andrews (1991) AR(1) plug-in bandwidth S_T for the Bartlett kernel.

    α(1) = Σ_a 4ρ_a²σ_a⁴ / ((1−ρ_a)⁶(1+ρ_a)²) / Σ_a σ_a⁴ / (1−ρ_a)⁴ and
    S_T = 1.1447 (α(1) T)^{1/3}, with ρ_a, σ_a² the AR(1) coefficient and innovation variance
    of score column a.
    """
    n = scores.shape[0]
    lagged = scores[:-1]
    lead = scores[1:]
    denom = np.einsum("ij,ij->j", lagged, lagged)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.einsum("ij,ij->j", lagged, lead) / denom
    rho = np.clip(np.nan_to_num(rho, nan=0.0), -RHO_CAP, RHO_CAP)
    innovations = lead - lagged * rho
    sigma2 = np.einsum("ij,ij->j", innovations, innovations) / max(n - 1, 1)
    num = float(np.sum(4 * rho**2 * sigma2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)))
    den = float(np.sum(sigma2**2 / (1 - rho) ** 4))
    if den <= 0.0:
        return 1.0
    return float(1.1447 * (num / den * n) ** (1.0 / 3.0))


def bartlett_weights(bandwidth: float, max_lag: int) -> FloatArray:
    lags = np.arange(max_lag + 1, dtype=np.float64)
    return np.asarray(np.clip(1.0 - lags / max(bandwidth, 1.0), 0.0, None), dtype=np.float64)


def long_run_sums(scores: FloatArray) -> FloatArray:
    """Newey-West long-run variance Σ_t s_t² + 2 Σ_l w_l Σ_t s_t s_{t−l}, per column.

    Each column gets its own Andrews bandwidth.
    """
    n = scores.shape[0]
    bandwidths = np.array(
        [andrews_bandwidth(scores[:, [j]]) for j in range(scores.shape[1])], dtype=np.float64
    )
    max_lag = int(min(n - 1, math.ceil(float(np.max(bandwidths, initial=1.0)))))
    if max_lag <= 32:
        acov = np.stack(
            [np.einsum("ij,ij->j", scores[lag:], scores[: n - lag]) for lag in range(max_lag + 1)]
        )
    else:
        acov = autocovariances(scores, max_lag)
    lags = np.arange(max_lag + 1, dtype=np.float64)[:, None]
    weights = np.clip(1.0 - lags / np.maximum(bandwidths, 1.0)[None, :], 0.0, None)
    weights[0] = 0.5
    return np.asarray(np.maximum(2.0 * np.sum(weights * acov, axis=0), 0.0), dtype=np.float64)


@dataclass(frozen=True)
class HacFit:
    """Pre-whitened OLS with a HAC covariance."""

    beta: FloatArray
    cov: FloatArray
    df: npt.NDArray[np.int64]
    phi: FloatArray


def hac_fit(y: FloatArray, x: FloatArray, order: int) -> HacFit:
    """Feasible GLS: OLS, AR(order) of its residual, filter y and X, OLS, Newey-West sandwich.

    cov(β) = (X*ᵀX*)⁺ S (X*ᵀX*)⁺ · n/(n−k), S = Γ₀ + Σ_l w_l (Γ_l + Γ_lᵀ), Γ_l = Σ_t g_t g_{t−l}ᵀ,
    g_t = x*_t e*_t.
    """
    beta0 = least_squares(x, y).coef
    phi = ar_fit(y - np.einsum("tk,k->t", x, beta0), order)
    ys = whiten(y, phi)
    xs = whiten(x, phi)
    fit = least_squares(xs, ys)
    beta = fit.coef
    e = ys - np.einsum("tk,k->t", xs, beta)
    g = xs * e[:, None]
    n, k = xs.shape
    bandwidth = andrews_bandwidth(g)
    max_lag = int(min(n - 1, math.ceil(bandwidth)))
    weights = bartlett_weights(bandwidth, max_lag)
    s = np.einsum("ti,tj->ij", g, g)
    for lag in range(1, max_lag + 1):
        if weights[lag] <= 0.0:
            break
        gamma = np.einsum("ti,tj->ij", g[lag:], g[:-lag])
        s += weights[lag] * (gamma + gamma.T)
    cov = fit.inverse @ s @ fit.inverse * (n / max(n - k, 1))
    return HacFit(
        beta=np.asarray(beta, dtype=np.float64),
        cov=np.asarray(cov, dtype=np.float64),
        df=effective_df(y.shape[0], k, phi, lag1_autocorrelation(x)),
        phi=phi,
    )


@dataclass(frozen=True)
class Screen:
    """Per-candidate coefficient, standard error and p-value when added to a base model."""

    beta: FloatArray
    se: FloatArray
    p: FloatArray
    df: npt.NDArray[np.int64]


def residualise(v: FloatArray, x: FloatArray) -> FloatArray:
    """v (a vector, or one series per column) minus its least-squares projection on the
    columns of x."""
    coef = least_squares(x, v).coef
    return np.asarray(v - np.einsum("ti,i...->t...", x, coef), dtype=np.float64)


def _base_projected(
    y: FloatArray, base: FloatArray, z_rows: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """y and every candidate row with the base design projected out, and the rows' sums of
    squares (Frisch–Waugh–Lovell)."""
    q0 = orthonormal(base)
    y_perp = project_out(y[None, :], q0)[0]
    z_perp = project_out(z_rows, q0)
    return y_perp, z_perp, np.einsum("ji,ji->j", z_perp, z_perp)


def _screened(beta: FloatArray, se: FloatArray, df: npt.NDArray[np.int64]) -> Screen:
    """Two-sided Student-t p-values; a candidate without a standard error gets p = 1."""
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.abs(beta) / se
    from scipy import stats  # over a second to import; scoring never needs it

    p = 2.0 * stats.t.sf(np.nan_to_num(t, nan=0.0, posinf=np.inf), df)
    p = np.where(np.isfinite(se), p, 1.0)
    return Screen(beta=beta, se=se, p=np.asarray(p, dtype=np.float64), df=df)


def screen(y: FloatArray, base: FloatArray, z_rows: FloatArray, order: int) -> Screen:
    """Test every row of z_rows (one candidate each), one at a time, added to the base design.

    For candidate j: the OLS residual of y on [base, z_j] gives the AR(order) filter φ_j
    (Cochrane-Orcutt), y, base and z_j are whitened with it and, by Frisch-Waugh-Lovell, the
    coefficient is β_j = z̃ᵀỹ / z̃ᵀz̃ with ỹ, z̃ the whitened series with the whitened base
    projected out; its HAC variance is LRV(z̃ e) / (z̃ᵀz̃)².
    """
    m, n = z_rows.shape
    k = base.shape[1] + 1
    y_perp, z_perp, zz0 = _base_projected(y, base, z_rows)
    with np.errstate(invalid="ignore", divide="ignore"):
        b0 = np.where(zz0 > 0, np.einsum("jt,t->j", z_perp, y_perp) / zz0, 0.0)
    beta = np.zeros(m)
    se = np.full(m, np.inf)
    df = np.ones(m, dtype=np.int64)
    rho = lag1_autocorrelation(z_rows.T)
    for j in range(m):
        if zz0[j] <= 0.0:
            continue
        phi = ar_fit(y_perp - b0[j] * z_perp[j], order)
        ys = whiten(y, phi)
        y_t, z_t = residualise(np.column_stack([ys, whiten(z_rows[j], phi)]), whiten(base, phi)).T
        zz = dot(z_t, z_t)
        if zz <= 0.0:
            continue
        beta[j] = dot(z_t, y_t) / zz
        e = y_t - beta[j] * z_t
        nw = ys.shape[0]
        lrv = float(long_run_sums((z_t * e)[:, None])[0])
        se[j] = math.sqrt(lrv * nw / max(nw - k, 1)) / zz
        df[j] = int(effective_df(n, k, phi, rho[j : j + 1])[0])
    return _screened(beta, se, df)


#: The FFT length of :func:`ar_model_fit` is at least this many times the record: the
#: autocovariances its AR spectrum stands for are aliased by γ(k ± M), which a persistence of
#: 1 − 1/n has decayed to e^(−31) of γ(0) at M = 32n.
SPECTRUM_OVERSAMPLING = 32


def ar_spectrum(phi: FloatArray, sigma2: float, size: int) -> FloatArray:
    """σ² / |1 − Σ_k φ_k e^(−iωk)|² at ω_m = 2πm / size, m = 0 … size // 2: the spectral density
    (times 2π) of an AR process, whose inverse DFT over ``size`` points is its autocovariances."""
    # The transfer function 1 − Σ φ_k e^(−iω_m k) at every ω_m is the DFT of the AR polynomial.
    transfer = sfft.rfft(np.concatenate(([1.0], -phi)), n=size)
    return np.asarray(sigma2 / np.maximum(np.abs(transfer) ** 2, 1e-300), dtype=np.float64)


def _quadratic_forms(columns: FloatArray, spectrum: FloatArray, size: int) -> FloatArray:
    """Xᵀ Σ X for the columns of X (samples × k), Σ_ts = γ(t − s) given by its spectrum on
    ``size`` ≥ 2n points: (1/size) Σ_m f_m X̂_m^H X̂_m, a one-sided sum of the real DFT."""
    transformed = sfft.rfft(columns, n=size, axis=0)
    weighted = transformed * _two_sided(spectrum, size)[:, None]
    return np.asarray(np.real(transformed.conj().T @ weighted) / size, dtype=np.float64)


def _fft_size(n: int, phi: FloatArray) -> int:
    """2n points for the lags of the record, and room for the AR model's autocovariances to
    decay to e^(−16) before they alias (at most :data:`SPECTRUM_OVERSAMPLING` · n)."""
    memory = 0.0
    if phi.shape[0]:
        largest = float(np.max(np.abs(np.roots(np.concatenate(([1.0], -phi))))))
        memory = math.inf if largest >= 1.0 else -1.0 / math.log(max(largest, 1e-300))
    wanted = min(SPECTRUM_OVERSAMPLING * n, 2 * n + 16.0 * memory)
    return int(sfft.next_fast_len(max(2 * n, math.ceil(wanted)), real=True))


def residual_spectrum(u: FloatArray, phi: FloatArray, k: int, size: int) -> FloatArray:
    """The spectrum of u's AR(φ) model on ``size`` points (:func:`ar_spectrum`), with the
    lowest frequencies raised to what u shows there when the model underrates them.

    A drift or a slow wave is no AR process of a few lags, and a model fitted to 10 Hz samples
    speaks for their fast dependence; a regressor that drifts too (a temperature, the state
    of charge) then looks far more certain than it is. As in :func:`effective_samples`, the
    periodogram I_j at the :data:`LOW_FREQUENCIES` lowest Fourier frequencies ω_j = 2πj/n is
    checked against the model (Σ 2 I_j / f(ω_j) is χ² with 2J degrees of freedom under it);
    when the check rejects at :data:`LOW_FREQUENCY_LEVEL`, f is at least the mean of those I_j
    up to ω_J.
    """
    n = u.shape[0]
    spectrum = ar_spectrum(phi, _innovations(u, phi, k), size)
    lowest = min(LOW_FREQUENCIES, (n - 1) // 2)
    if lowest <= 0:
        return spectrum
    at = np.rint(np.arange(1, lowest + 1) * size / n).astype(np.int64)
    floor = _drift_level(u - float(np.mean(u)), spectrum[at])
    if floor is not None:
        top = int(at[-1])
        spectrum[: top + 1] = np.maximum(spectrum[: top + 1], floor)
    return spectrum


def _drift_level(centred: FloatArray, model: FloatArray) -> float | None:
    """The mean periodogram of ``centred`` at its lowest Fourier frequencies ω_j = 2πj/n,
    j = 1 … len(model), when it rejects ``model`` (the AR spectrum there) at
    :data:`LOW_FREQUENCY_LEVEL` (Σ 2 I_j / f(ω_j) is χ² with 2J degrees of freedom under the
    model); None when the model holds."""
    n, lowest = centred.shape[0], model.shape[0]
    periodogram = np.abs(np.fft.rfft(centred)[1 : lowest + 1]) ** 2 / n
    from scipy import stats  # over a second to import; scoring never needs it

    limit = float(stats.chi2.ppf(1.0 - LOW_FREQUENCY_LEVEL, 2 * lowest))
    if float(np.sum(2.0 * periodogram / np.maximum(model, 1e-300))) > limit:
        return float(np.mean(periodogram))
    return None


def _innovations(u: FloatArray, phi: FloatArray, k: int) -> float:
    """The AR model's innovation variance, with the k regressors' degrees of freedom."""
    e = whiten(u, phi)
    m = int(e.shape[0])
    return dot(e, e) / max(m - k, 1)


def ar_model_fit(y: FloatArray, x: FloatArray, order: int) -> HacFit:
    """OLS, with the covariance OLS has when its residual is the AR(order) process fitted to it.

    β = (XᵀX)⁻¹Xᵀy. The residual u = y − Xβ gets AR coefficients φ (:func:`ar_fit`, Kendall's
    bias added back) and innovation variance σ²; Σ_ts = γ(t − s) are that model's
    autocovariances, and cov(β) = (XᵀX)⁻¹ XᵀΣX (XᵀX)⁻¹ exactly, computed in the frequency
    domain. Each coefficient's degrees of freedom are its equivalent independent samples,
    n γ(0) [(XᵀX)⁻¹]_jj / cov_jj, less k.

    Unlike the filtered (Cochrane–Orcutt) fit, the point estimate weighs each frequency by its
    power in X rather than by the inverse of the residual's: where the model and the
    measurement are not coherent (timing jitter, a noisy measured regressor), the fast part of
    a regressor is noise, and filtering by a persistent residual's AR model, which amplifies
    exactly the fast part, dilutes its coefficient toward zero.
    """
    n, k = x.shape
    fit = least_squares(x, y)
    beta = np.asarray(fit.coef, dtype=np.float64)
    u = y - np.einsum("tk,k->t", x, beta)
    phi = ar_fit(u, order)
    size = _fft_size(n, phi)
    spectrum = residual_spectrum(u, phi, k, size)
    meat = _quadratic_forms(x, spectrum, size)
    cov = fit.inverse @ meat @ fit.inverse
    gamma0 = _variance_of(spectrum, size)
    return HacFit(
        beta=beta,
        cov=np.asarray(cov, dtype=np.float64),
        df=_equivalent_df(n, k, gamma0 * np.diag(fit.inverse), np.diag(cov)),
        phi=phi,
    )


def _variance_of(spectrum: FloatArray, size: int) -> float:
    """γ(0) of the process whose spectrum on ``size`` points is given."""
    return float(np.sum(_two_sided(spectrum, size))) / size


def _two_sided(spectrum: FloatArray, size: int) -> FloatArray:
    """A real signal's one-sided spectrum (m = 0 … size // 2) weighted so that its sum is the
    sum over all ``size`` frequencies: every bin twice but zero and, for an even size, Nyquist."""
    weights = np.full(spectrum.shape[0], 2.0)
    weights[0] = 1.0
    if size % 2 == 0:
        weights[-1] = 1.0
    return np.asarray(weights * spectrum, dtype=np.float64)


def _equivalent_df(n: int, k: int, white: FloatArray, actual: FloatArray) -> npt.NDArray[np.int64]:
    """n · (the variance white noise of the same level would give) / (the actual one), less k:
    the independent samples a coefficient's estimate is worth."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(actual > 0.0, white / actual, 1.0)
    eff = n * np.clip(np.nan_to_num(ratio, nan=1.0, posinf=1.0), 0.0, 1.0) - k
    # White noise gives a ratio of 1 up to rounding: n − k, not one fewer.
    return np.asarray(np.clip(np.floor(eff + 1e-6), 1, max(n - k, 1)), dtype=np.int64)


def ar_model_screen(y: FloatArray, base: FloatArray, z_rows: FloatArray, order: int) -> Screen:
    """:func:`screen` with :func:`ar_model_fit`'s estimator: every row of z_rows added, one at a
    time, to the base design. By Frisch–Waugh–Lovell β_j = z̃ᵀỹ / z̃ᵀz̃ with z̃, ỹ the
    candidate and y with the base projected out, and var β_j = z̃ᵀΣ_j z̃ / (z̃ᵀz̃)², Σ_j the
    AR model of that fit's residual."""
    m, n = z_rows.shape
    k = base.shape[1] + 1
    y_perp, z_perp, zz = _base_projected(y, base, z_rows)
    beta = np.zeros(m)
    se = np.full(m, np.inf)
    df = np.ones(m, dtype=np.int64)
    for j in range(m):
        if zz[j] <= 0.0:
            continue
        beta[j] = dot(z_perp[j], y_perp) / zz[j]
        u = y_perp - beta[j] * z_perp[j]
        phi = ar_fit(u, order)
        size = _fft_size(n, phi)
        spectrum = residual_spectrum(u, phi, k, size)
        variance = float(_quadratic_forms(z_perp[j][:, None], spectrum, size)[0, 0]) / zz[j] ** 2
        se[j] = math.sqrt(max(variance, 0.0))
        white = _variance_of(spectrum, size) / zz[j]
        df[j] = int(_equivalent_df(n, k, np.array([white]), np.array([variance]))[0])
    return _screened(beta, se, df)


def effective_samples(u: FloatArray, order: int) -> float:
    """Samples of white noise that would estimate the mean of u as precisely: n γ₀ / LRV,
    at least 1 and at most n.

    LRV, the long-run variance Σ_k γ_k, is that of u's AR(order) model, σ²_ε / (1 − Σφ)²,
    right for persistent and oscillating noise alike. A drift or a slow wave is no such
    process, and an AR fit of a few lags makes little sense of it; it shows as more power at
    the lowest frequencies than the AR model allows. So the periodogram I_j = |Σ_t u_t
    e^{−iω_j t}|² / n at the :data:`LOW_FREQUENCIES` lowest Fourier frequencies is compared
    with the AR spectrum g(ω) = σ²_ε / |1 − Σ_k φ_k e^{−iωk}|² there (g(0) = LRV): when
    Σ_j 2 I_j / g(ω_j), χ² with 2J degrees of freedom under the model, exceeds its
    1 − :data:`LOW_FREQUENCY_LEVEL` quantile, LRV is the larger of the AR value and the mean
    of those I_j.
    """
    n = u.shape[0]
    if not varies(u):
        return float(n)
    centred = u - float(np.mean(u))
    gamma0 = dot(centred, centred) / n
    phi = ar_fit(centred, order)
    if phi.shape[0]:
        innovations = whiten(centred, phi)
        sigma2 = dot(innovations, innovations) / innovations.shape[0]
    else:
        sigma2 = gamma0
    lowest = min(LOW_FREQUENCIES, (n - 1) // 2)
    omega = 2.0 * np.pi * np.arange(1, lowest + 1) / n
    lags = np.arange(1, phi.shape[0] + 1)
    transfer = 1.0 - np.exp(-1j * np.outer(omega, lags)) @ phi
    model = sigma2 / np.maximum(np.abs(transfer) ** 2, 1e-300)
    long_run = sigma2 / max((1.0 - float(np.sum(phi))) ** 2, 1e-300)
    if lowest > 0 and sigma2 > 0.0:
        drift = _drift_level(centred, model)
        if drift is not None:
            long_run = max(long_run, drift)
    if long_run <= 0.0:
        return float(n)
    return float(min(max(n * gamma0 / long_run, 1.0), n))


@dataclass(frozen=True)
class BlockLength:
    """Politis & White's (2004) automatic block lengths for a bootstrap of the mean of x.

    Attributes
    ----------
    stationary:
        Expected block length for the stationary bootstrap (Politis & Romano 1994).
    circular:
        Block length for the circular (and the moving) block bootstrap.
    variance:
        γ̂₀, the variance of x (divisor n).
    long_run_variance:
        The flat-top lag-window estimate Σ_{|k|≤M} λ(k/M) γ̂_k of Σ_k γ_k, the variance of
        √n times the mean (it can come out at or below zero on a short, strongly
        anti-persistent series).
    bandwidth:
        M, the lags that estimate used.
    """

    stationary: float
    circular: float
    variance: float
    long_run_variance: float
    bandwidth: int


def politis_white(x: FloatArray) -> BlockLength:
    """Block lengths by Politis & White (2004) with the correction of Patton, Politis & White
    (2009), as ``arch.bootstrap.optimal_block_length`` computes them.

    m̂ is the first lag from which k_n = max(5, ⌊log₁₀ n⌋) consecutive autocorrelations lie
    within ±2√(log₁₀ n / n), M = 2 max(m̂, 1) (at most √n + k_n), and with the flat-top window
    λ(t) = min(1, 2(1 − |t|)), Ĝ = Σ_{|k|≤M} λ(k/M)|k|γ̂_k and ĝ = Σ_{|k|≤M} λ(k/M)γ̂_k:
    b = (2Ĝ² / (c ĝ²))^{1/3} n^{1/3}, c = 2 (stationary) or 4/3 (circular), at most
    min(3√n, n/3). As in arch, the autocorrelation at lag i divides by the sums of squares of
    the samples after the first i + 1 and before the last i + 1. A series without dependence
    can get a length under one sample (blocks of one); one of fewer than three samples, or a
    constant one, gets 1.
    """
    u = np.asarray(x, dtype=np.float64)
    n = u.shape[0]
    if n < 3 or not varies(u):
        return BlockLength(1.0, 1.0, 0.0, 0.0, 0)
    eps = u - float(np.mean(u))
    kn = max(5, int(math.log10(n)))
    m_max = min(math.ceil(math.sqrt(n)) + kn, n - 2)
    squares = np.cumsum(eps * eps)
    acv = autocovariances(eps[:, None], m_max)[:, 0] / n
    lags = np.arange(m_max + 1)
    after = squares[-1] - squares[lags]
    before = squares[n - lags - 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = np.abs(acv * n) / np.sqrt(after * before)
    inside = np.nan_to_num(corr, nan=np.inf) < 2.0 * math.sqrt(math.log10(n) / n)
    runs = np.convolve(inside.astype(np.int64), np.ones(kn, dtype=np.int64), mode="valid")
    first = np.flatnonzero(runs[: m_max - kn + 1] == kn)
    m = min(2 * max(int(first[0]), 1), m_max) if first.shape[0] else m_max
    k = np.arange(1, m + 1, dtype=np.float64)
    window = np.minimum(1.0, 2.0 * (1.0 - k / m))
    g = float(np.sum(2.0 * window * k * acv[1 : m + 1]))
    long_run = float(acv[0] + np.sum(2.0 * window * acv[1 : m + 1]))
    b_max = float(math.ceil(min(3.0 * math.sqrt(n), n / 3.0)))
    if long_run == 0.0:
        return BlockLength(b_max, b_max, float(acv[0]), long_run, m)
    ratio = 2.0 * g * g / (long_run * long_run) * n
    return BlockLength(
        stationary=min((ratio / 2.0) ** (1.0 / 3.0), b_max),
        circular=min((ratio * 0.75) ** (1.0 / 3.0), b_max),
        variance=float(acv[0]),
        long_run_variance=long_run,
        bandwidth=m,
    )


def ljung_box(x: npt.ArrayLike, lags: Sequence[int], *, alpha: float = 0.05) -> Whiteness:
    """Ljung-Box (1978) portmanteau test of no autocorrelation up to each lag h.

    Notes
    -----
    Q(h) = n (n + 2) Σ_{k=1}^{h} ρ̂_k² / (n − k), which is χ²(h) under white noise. The reported
    statistic is the Q(h) with the smallest p-value; that p-value is multiplied by the number
    of lags (Bonferroni), so that testing several lags does not inflate the error rate.
    """
    u = np.asarray(x, dtype=np.float64)
    n = u.shape[0]
    use = tuple(sorted({int(h) for h in lags if 1 <= int(h) < n}))
    if not use:
        return Whiteness(lags=(), statistic=0.0, p_value=1.0, white=True)
    centred = u - float(np.mean(u))
    acov = autocovariances(centred[:, None], max(use))[:, 0]
    if acov[0] <= 0.0:
        return Whiteness(lags=use, statistic=0.0, p_value=1.0, white=True)
    rho = acov[1:] / acov[0]
    terms = rho**2 / (n - np.arange(1, max(use) + 1))
    best_q, best_p = 0.0, 1.0
    for h in use:
        q = float(n * (n + 2) * np.sum(terms[:h]))
        from scipy import stats

        p = float(stats.chi2.sf(q, h))
        if p < best_p or h == use[0]:
            best_q, best_p = q, p
    adjusted = min(1.0, best_p * len(use))
    return Whiteness(lags=use, statistic=best_q, p_value=adjusted, white=adjusted >= alpha)


def dominant_frequencies(u: FloatArray, dt: float) -> tuple[float, ...]:
    """The largest local maxima (DC excluded) of the Welch (1967) spectrum, in Hz."""
    n = u.shape[0]
    if n < 8 or not np.any(u != u[0]):
        return ()
    from scipy import signal as sps

    freqs, power = sps.welch(u, fs=1.0 / dt, nperseg=min(n, 4096))
    if power.shape[0] < 3 or float(np.max(power)) <= 0.0:
        return ()
    padded = np.concatenate(([-np.inf], power[1:], [-np.inf]))
    peaks, _ = sps.find_peaks(padded)
    peaks = peaks[(peaks >= 1) & (peaks < power.shape[0])]
    if peaks.shape[0] == 0:
        return ()
    top = peaks[np.argsort(power[peaks])[::-1][:N_PEAKS]]
    return tuple(float(freqs[i]) for i in top)

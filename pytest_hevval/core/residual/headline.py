"""The simulated signal itself: its timing (the lag of the peak cross-correlation) and the gain
and offset of reference ≈ gain · simulated + offset on the lag-aligned pair, tested and sized by
one least-squares fit with the AR-model covariance."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..lag import search_lag
from ..stats import FloatArray, ar_model_fit, block_means
from .inference import _interval, _p_value
from .inputs import _varies
from .thresholds import _DEFAULT_MAX_LAG_S, GAIN_MATERIALITY, OFFSET_MATERIALITY


def _timing(
    ref: FloatArray, sim: FloatArray, dt: float, max_lag_s: float | None, sim_varies: bool
) -> tuple[int, int]:
    """The lag (samples) of the peak mean-removed cross-correlation, and the half-width of
    the search (samples)."""
    n = ref.shape[0]
    window_s = _DEFAULT_MAX_LAG_S if max_lag_s is None else float(max_lag_s)
    # At least 10 samples must remain where both records overlap at the searched lag.
    max_lag = int(min(max(window_s, 0.0) / dt, (n - 10) if max_lag_s is not None else n // 4))
    # A constant signal correlates equally with every shift: there is no lag to find.
    return (search_lag(ref, sim, max_lag).lag if sim_varies and _varies(ref) else 0), max_lag


@dataclass(frozen=True)
class _Headline:
    """Gain and offset of reference ≈ gain · simulated + offset on the lag-aligned pair."""

    gain: float
    gain_interval: tuple[float, float]
    gain_significant: bool
    offset: float
    offset_interval: tuple[float, float]
    offset_p: float
    offset_significant: bool


def _gain_and_offset(
    ref: FloatArray,
    sim: FloatArray,
    lag: int,
    order: int,
    alpha: float,
    max_samples: int,
    sim_varies: bool,
) -> _Headline:
    n = ref.shape[0]
    if lag >= 0:
        ref_a, sim_a = ref[lag:], sim[: n - lag]
    else:
        ref_a, sim_a = ref[: n + lag], sim[-lag:]
    factor_a = max(1, math.ceil(ref_a.shape[0] / max_samples))
    ref_g = block_means(ref_a, factor_a)
    sim_g = block_means(sim_a, factor_a)
    ref_range = float(np.ptp(ref)) or float(np.max(np.abs(ref))) or 1.0
    design = (
        np.column_stack([np.ones_like(sim_g), sim_g])
        if sim_varies
        else np.ones((sim_g.shape[0], 1))
    )
    response = ref_g if sim_varies else ref_g - sim_g
    # The simulated signal is no candidate that could match the residual by chance: tested
    # and sized by the same least-squares fit (see _fitted_terms for why not the filtered one).
    head = ar_model_fit(response, design, order)
    head_se = np.sqrt(np.maximum(np.diag(head.cov), 0.0))
    offset = float(head.beta[0])
    offset_interval = _interval(offset, float(head_se[0]), int(head.df[0]), alpha)
    offset_p = _p_value(offset, float(head_se[0]), int(head.df[0]))
    # Gain and offset are two tests of one question ("is the simulated signal itself off?"):
    # Bonferroni over the pair keeps the chance of a false headline at most alpha.
    headline_level = alpha / 2.0
    offset_significant = (
        offset_p <= headline_level
        and not (offset_interval[0] <= 0.0 <= offset_interval[1])
        and abs(offset) > OFFSET_MATERIALITY * ref_range
    )
    if not sim_varies:
        return _Headline(
            1.0, (1.0, 1.0), False, offset, offset_interval, offset_p, offset_significant
        )
    gain = float(head.beta[1])
    gain_se = float(head_se[1])
    gain_interval = _interval(gain, gain_se, int(head.df[1]), alpha)
    gain_significant = (
        _p_value(gain - 1.0, gain_se, int(head.df[1])) <= headline_level
        and not (gain_interval[0] <= 1.0 <= gain_interval[1])
        and abs(gain - 1.0) > GAIN_MATERIALITY
    )
    return _Headline(
        gain, gain_interval, gain_significant, offset, offset_interval, offset_p, offset_significant
    )

"""Which candidates enter the joint model: Holm-guarded forward selection on the filtered GLS
tests at every time scale, with the gatekeeping order's weights; then each candidate's finding
(the selected ones from the joint model, the others tested alone) and their ranking."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from ..stats import FloatArray, Screen, ar_model_fit, dot, hac_fit, orthonormal, project_out, screen
from .candidates import _Scale, _Series
from .findings import CandidateFinding
from .inference import _excludes_zero, _full_rate_r2, _interval, _p_value, _scaled
from .thresholds import _COLLINEAR, MIN_EXPLAINED_INCREASE


def _holm_weights(first: npt.NDArray[np.bool_]) -> FloatArray:
    """Weights of the weighted Holm procedure: the first family of the gatekeeping order (the
    automatic terms, the loads in the signal's dimension and the spec's declared suspects)
    shares half of the level, every other candidate the other half; equal weights when there
    are only one or the other."""
    d = int(np.count_nonzero(first))
    if d == 0 or d == first.shape[0]:
        return np.ones(first.shape[0])
    return np.where(first, (first.shape[0] - d) / d, 1.0)


def _forward_selection(
    scales: Sequence[_Scale],
    *,
    alpha: float,
    max_selected: int,
    weights: FloatArray,
    first: npt.NDArray[np.bool_] | None = None,
) -> tuple[list[int], list[float], list[FloatArray]]:
    """Holm-guarded forward selection; (selected rows, their levels, the final design per scale).

    Gatekeeping order: while a candidate of the first family (``first``) passes, only those
    can enter; the others are tested on what the first family's selected effects leave. A
    temperature that follows a heater then explains only what the heater's power does not.

    A candidate is tested at every scale and passes when its smallest p-value, times the number
    of scales (Bonferroni), is under its weighted Holm level α·w_j / Σ w of the candidates not
    yet selected (Holm 1979): an effect counts at the time scale where it acts, and the user's
    declared suspects weigh more than the many channels tried automatically. The largest
    increase of R² on the regression grid (the first scale) picks among those that pass.
    """
    fine = scales[0]
    r_g = fine.r
    ng = r_g.shape[0]
    m = fine.z_rows.shape[0]
    rc_g = r_g - float(np.mean(r_g))
    sst_g = dot(rc_g, rc_g)
    selected: list[int] = []
    holm_levels: list[float] = []
    remaining_idx = list(range(m))
    bases = [np.ones((sc.r.shape[0], 1)) for sc in scales]
    while remaining_idx and len(selected) < max_selected and sst_g > 0.0:
        levels = alpha * weights / float(np.sum(weights[remaining_idx]))
        q = orthonormal(bases[0])
        resid = project_out(r_g[None, :], q)[0]
        z_rem = fine.z_rows[remaining_idx]
        z_perp = project_out(z_rem, q)
        zz = np.einsum("jt,jt->j", z_perp, z_perp)
        with np.errstate(invalid="ignore", divide="ignore"):
            gain_r2 = np.where(
                zz / ng > _COLLINEAR, np.einsum("jt,t->j", z_perp, resid) ** 2 / zz / sst_g, 0.0
            )
        # Only candidates that would add a material share need the (costly) test.
        material = np.flatnonzero(gain_r2 >= MIN_EXPLAINED_INCREASE)
        if material.shape[0] == 0:
            break
        chosen_rows = [remaining_idx[int(j)] for j in material]
        p = np.min(
            [
                screen(sc.r, base, sc.z_rows[chosen_rows], sc.order).p
                for sc, base in zip(scales, bases, strict=True)
            ],
            axis=0,
        ) * len(scales)
        passed = p <= levels[chosen_rows]
        if first is not None:
            leading = first[chosen_rows]
            if np.any(passed & leading):
                passed &= leading
        if not np.any(passed):
            break
        pick = int(material[int(np.argmax(np.where(passed, gain_r2[material], -np.inf)))])
        chosen = remaining_idx.pop(pick)
        selected.append(chosen)
        holm_levels.append(float(levels[chosen]))
        bases = [
            np.column_stack([base, sc.z_rows[chosen]])
            for sc, base in zip(scales, bases, strict=True)
        ]
    return selected, holm_levels, bases


def _joint_model(
    r: FloatArray,
    r_g: FloatArray,
    kept: list[_Series],
    selected: list[int],
    holm_levels: list[float],
    base: FloatArray,
    order: int,
    alpha: float,
) -> tuple[list[CandidateFinding], float, FloatArray, FloatArray]:
    """The selected candidates fitted jointly: findings, explained share, what is left."""
    findings: list[CandidateFinding] = []
    joint_r2_full: list[float] = []
    full_cols: list[FloatArray] = []
    for idx in selected:
        full_cols.append(kept[idx].full)
        joint_r2_full.append(_full_rate_r2(r, full_cols))
    explained = joint_r2_full[-1] if joint_r2_full else 0.0
    remaining_full = r.copy()
    remaining_grid = r_g.copy()
    if not selected:
        return findings, explained, remaining_full, remaining_grid
    # Intervals of selected candidates use the noise model of the final joint model.
    test = hac_fit(r_g, base, order)
    test_se = np.sqrt(np.maximum(np.diag(test.cov), 0.0))
    joint = ar_model_fit(r_g, base, order)
    se = np.sqrt(np.maximum(np.diag(joint.cov), 0.0))
    for pos, idx in enumerate(selected):
        s = kept[idx]
        b_std = float(joint.beta[pos + 1])
        se_std = float(se[pos + 1])
        coef = b_std / s.std
        df = int(joint.df[pos + 1])
        p = _p_value(float(test.beta[pos + 1]), float(test_se[pos + 1]), int(test.df[pos + 1]))
        interval = _interval(coef, se_std / s.std, df, alpha)
        remaining_full -= coef * (s.full - s.mean)
        remaining_grid -= coef * (s.grid - s.mean)
        findings.append(
            CandidateFinding(
                name=s.name,
                kind=s.kind,
                explained_fraction=_full_rate_r2(r, [s.full]),
                joint_explained_fraction=joint_r2_full[pos],
                coefficient=coef * s.unit,
                interval=_scaled(interval, s.unit),
                p_value=p,
                significant=p <= holm_levels[pos] and _excludes_zero(interval),
                selected=True,
                rank=0,
            )
        )
    return findings, explained, remaining_full, remaining_grid


def _alone_findings(
    r: FloatArray,
    kept: list[_Series],
    selected: list[int],
    alone: Screen | None,
    sizes: Screen | None,
    alpha: float,
    weights: FloatArray,
) -> list[CandidateFinding]:
    """Each candidate not selected, tested alone with an intercept (weighted Bonferroni over
    all, with the weights of the selection) and sized by least squares."""
    if alone is None or sizes is None:
        return []
    findings = []
    for j, s in enumerate(kept):
        if j in selected:
            continue
        coef = float(sizes.beta[j]) / s.std
        p = float(alone.p[j])
        interval = _interval(coef, float(sizes.se[j]) / s.std, int(sizes.df[j]), alpha)
        findings.append(
            CandidateFinding(
                name=s.name,
                kind=s.kind,
                explained_fraction=_full_rate_r2(r, [s.full]),
                joint_explained_fraction=None,
                coefficient=coef * s.unit,
                interval=_scaled(interval, s.unit),
                p_value=p,
                significant=p <= alpha * float(weights[j]) / float(np.sum(weights))
                and _excludes_zero(interval),
                selected=False,
                rank=0,
            )
        )
    return findings


def _timing_significant(ordered: Sequence[CandidateFinding], lag: int, dt: float) -> bool:
    """Timing counts only when the delay survived the forward selection, with the sign of the
    searched lag and a size of at least half a sample: the lag search maximises the fit over
    many lags, so an unadjusted test of the lag it picked would see delays in pure noise."""
    lag_finding = next((f for f in ordered if f.kind == "lag"), None)
    if lag_finding is None or lag == 0:
        return False
    return (
        lag_finding.selected
        and lag_finding.significant
        and (lag_finding.coefficient > 0) == (lag < 0)
        and abs(lag_finding.coefficient) >= dt / 2.0
    )


def _rank(findings: Sequence[CandidateFinding]) -> list[CandidateFinding]:
    """Selected findings in order of entry, then the rest by explained fraction.

    A significant offset is not part of the forward selection; it goes before the first
    selected candidate that it out-explains.
    """
    chosen = [f for f in findings if f.selected and f.kind != "offset"]
    rest = sorted((f for f in findings if not f.selected), key=lambda f: -f.explained_fraction)
    for f in findings:
        if f.selected and f.kind == "offset":
            at = next(
                (i for i, c in enumerate(chosen) if f.explained_fraction > c.explained_fraction),
                len(chosen),
            )
            chosen.insert(at, f)
    return [replace(f, rank=i + 1) for i, f in enumerate([*chosen, *rest])]

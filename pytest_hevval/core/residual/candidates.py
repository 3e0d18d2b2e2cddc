"""Candidate series on the diagnosis's grids: the automatic lag and gain candidates beside the
user's, block means on the regression grid and on the slow scale, constant and collinear
candidates dropped (with a note), and candidates that measure one effect grouped under the
member that names it."""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..stats import FloatArray, ar_order, block_means, dot
from .findings import Note
from .inputs import _free_name, _UserSeries
from .thresholds import (
    _COLLINEAR,
    _DIMENSION_NAMING_SHARE,
    _NAMING_PREFERENCE,
    _NAMING_TOLERANCE,
    GENERIC_KINDS,
    GROUP_MIN_CORRELATION,
    MIN_SLOW_BLOCKS,
    SLOW_SCALE_S,
)


@dataclass
class _Series:
    name: str
    kind: str
    full: FloatArray
    grid: FloatArray
    mean: float
    std: float
    # Multiplies a coefficient fitted on the rescaled data to give it in the caller's units.
    unit: float
    # Other candidates that measure the same thing (see _grouped); this one names the effect.
    members: tuple[str, ...] = ()


def _candidate_series(
    sim: FloatArray,
    lag: int,
    dt: float,
    window: slice,
    factor: int,
    user: _UserSeries,
    units: Mapping[str, float],
    names: set[str],
) -> list[_Series]:
    """The automatic lag and gain candidates, then the user's, on the analysis window."""
    kinds = {kind for _, kind, _ in user}
    auto: _UserSeries = []
    # A user channel may already be called "lag" or "gain"; the automatic one then steps aside.
    if "lag" not in kinds:
        auto.append((_free_name("lag", names), "lag", _delay_slope(sim, lag, dt)[window]))
    if "gain" not in kinds:
        auto.append((_free_name("gain", names), "gain", sim[window]))
    series: list[_Series] = []
    for label, kind, values in [*auto, *((a, b, v[window]) for a, b, v in user)]:
        grid = block_means(values, factor)
        unit = units.get(label, 1.0)
        series.append(
            _Series(label, kind, values, grid, float(np.mean(grid)), float(np.std(grid)), unit)
        )
    return series


def _delay_slope(sim: FloatArray, lag: int, dt: float) -> FloatArray:
    """The series whose coefficient is the delay d of the simulation, in seconds.

    If sim(t) = ref(t − d) then r(t) = sim(t + d) − sim(t) = d · [sim(t + d) − sim(t)] / d, so
    the secant slope over the lag found by the search (d = −lag·dt) explains a pure delay
    exactly with coefficient d; without a lag it is the derivative, the first-order term of
    the same expansion. Samples whose shifted partner falls outside the record repeat the edge
    value; the diagnosis only fits the samples where it exists.
    """
    if lag == 0:
        return np.asarray(np.gradient(sim, dt), dtype=np.float64)
    n = sim.shape[0]
    ahead = sim[np.clip(np.arange(n) - lag, 0, n - 1)]
    return np.asarray((ahead - sim) / (-lag * dt), dtype=np.float64)


def _independent(
    series: list[_Series], ng: int, notes: list[Note]
) -> tuple[list[_Series], FloatArray]:
    """Candidates that are neither constant nor collinear, and their standardised rows."""
    usable: list[_Series] = []
    for s in series:
        scale = max(float(np.max(np.abs(s.grid))), 1e-300)
        if s.std <= 1e-12 * scale:
            notes.append(Note("constant", candidate=s.name))
        else:
            usable.append(s)
    # Sequential Cholesky of the Gram matrix of [1, z₁, z₂, …]: the pivot of z_j is the part
    # of its variance left after projecting out the constant and every candidate kept before
    # it, so one pass finds all collinear ones; a dropped candidate adds no pivot.
    standardised = np.empty((len(usable) + 1, ng))
    standardised[0] = 1.0 / math.sqrt(ng)
    for i, s in enumerate(usable):
        standardised[i + 1] = (s.grid - s.mean) / s.std
    from scipy import linalg as sla  # a tenth of a second to import; scoring never needs it

    gram = np.einsum("it,jt->ij", standardised, standardised)
    factor_rows = np.zeros_like(gram)
    factor_rows[0, 0] = math.sqrt(gram[0, 0])
    kept: list[_Series] = []
    kept_rows: list[int] = [0]
    for i, s in enumerate(usable, start=1):
        cols = np.asarray(kept_rows)
        below = sla.solve_triangular(
            factor_rows[np.ix_(cols, cols)], gram[cols, i], lower=True, check_finite=False
        )
        pivot = gram[i, i] - float(np.sum(below**2))
        if pivot / gram[i, i] >= _COLLINEAR:
            factor_rows[i, cols] = below
            factor_rows[i, i] = math.sqrt(pivot)
            kept.append(s)
            kept_rows.append(i)
            continue
        corr = np.abs(gram[kept_rows[1:], i]) / ng
        best = int(np.argmax(corr)) if kept else -1
        if best >= 0 and corr[best] ** 2 >= 1.0 - _COLLINEAR:
            notes.append(Note("duplicate", candidate=s.name, other=kept[best].name))
        else:
            notes.append(Note("collinear", candidate=s.name))
    rows = kept_rows[1:]
    z_rows = np.ascontiguousarray(standardised[rows]) if kept else np.zeros((0, ng))
    return kept, z_rows


def _grouped(
    series: list[_Series],
    r_g: FloatArray,
    declared: Sequence[Collection[str]] = (),
    in_dimension: Collection[str] = (),
) -> list[_Series]:
    """One series per effect: candidates that measure the same thing become one group.

    Candidates are taken by how much of the residual each explains alone, best first; each
    joins the first group whose leading member it correlates with at least
    :data:`GROUP_MIN_CORRELATION` (either sign), or starts a group of its own. A group is named
    by its best member (the spec's own expression, then a logged channel, when members explain
    within 5 % as much; a member in the scored signal's dimension when it explains at least
    half as much) and lists the others as ``members``. Only that member enters the
    selection: offered side by side, near copies split one effect between them with opposite
    signs, and none is credited with it. The automatic lag and gain are never grouped. The
    spec's declared groups are groups from the start, whatever their correlation.
    """
    pool = [i for i, s in enumerate(series) if s.kind not in GENERIC_KINDS and s.std > 0.0]
    if len(pool) < 2:
        return series
    ng = r_g.shape[0]
    rows = np.stack([(series[i].grid - series[i].mean) / series[i].std for i in pool])
    rc = r_g - float(np.mean(r_g))
    sst = dot(rc, rc)
    score = (rows @ rc) ** 2 / (ng * sst) if sst > 0.0 else np.zeros(len(pool))
    corr = np.abs(rows @ rows.T) / ng
    order = [int(a) for a in np.argsort(-score, kind="stable")]
    position = {series[i].name: a for a, i in enumerate(pool)}
    groups: list[list[int]] = []
    placed: set[int] = set()
    for names in declared:
        found = sorted((position[n] for n in names if n in position), key=order.index)
        if found:
            groups.append(found)
            placed.update(found)
    for a in order:
        if a in placed:
            continue
        home = next((g for g in groups if corr[a, g[0]] >= GROUP_MIN_CORRELATION), None)
        if home is None:
            groups.append([int(a)])
        else:
            home.append(int(a))
    leaders: dict[int, _Series] = {}
    dropped: set[int] = set()
    for g in groups:
        best = float(score[g[0]])

        def naming(a: int, best: float = best) -> tuple[int, int, int, float]:
            near = score[a] >= (1.0 - _NAMING_TOLERANCE) * best
            kind = series[pool[a]].kind
            return (
                0 if kind == "declared" and near else 1,
                # A coarse or stuck load channel still names the effect before a temperature
                # that follows the load more smoothly, as long as it explains half as much.
                0
                if series[pool[a]].name in in_dimension
                and score[a] >= _DIMENSION_NAMING_SHARE * best
                else 1,
                _NAMING_PREFERENCE.get(kind, 3) if near else 9,
                -float(score[a]),
            )

        lead = min(g, key=naming)
        members = tuple(series[pool[a]].name for a in g if a != lead)
        leaders[pool[lead]] = replace(series[pool[lead]], members=members)
        dropped.update(pool[a] for a in g if a != lead)
    return [leaders.get(i, s) for i, s in enumerate(series) if i not in dropped]


@dataclass(frozen=True)
class _Scale:
    """The residual and the standardised candidates on one grid of block means."""

    factor: int
    r: FloatArray
    z_rows: FloatArray
    order: int


def _slow_scale(r: FloatArray, kept: Sequence[_Series], dt: float, factor: int) -> _Scale | None:
    """The grid of :data:`SLOW_SCALE_S` block means, when it is coarser than the regression
    grid and the record holds at least :data:`MIN_SLOW_BLOCKS` of its blocks."""
    slow = max(1, round(SLOW_SCALE_S / dt))
    if slow <= factor or r.shape[0] // slow < MIN_SLOW_BLOCKS:
        return None
    r_s = block_means(r, slow)
    rows = np.empty((len(kept), r_s.shape[0]))
    for i, s in enumerate(kept):
        block = block_means(s.full, slow)
        spread = float(np.std(block))
        rows[i] = (block - float(np.mean(block))) / spread if spread > 0.0 else 0.0
    return _Scale(slow, r_s, rows, ar_order(r_s - float(np.mean(r_s))))

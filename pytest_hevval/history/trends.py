"""Trends over model versions: a table of Φ and λ per run, step detection, and a plot.

:func:`detect_steps` is pure (a sequence in, steps out) so that it can be tested on synthetic
series; :func:`plot_history` imports matplotlib only when called.
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.registry import describe, order_names
from ..escape import plot_text
from ..files import write_atomic
from ..results.recorded import RecordedRun, RecordedSignal, RecordedSpec
from ._base import HistoryError

__all__ = [
    "HistoryRow",
    "Step",
    "characteristic_names",
    "detect_steps",
    "history_table",
    "plot_history",
    "render_history_table",
    "row_series",
]

# 1.4826 × MAD estimates σ of normal noise; the differences of white noise have σ·√2.
_MAD_TO_SIGMA = 1.4826
_PLOT_SUFFIXES = (".png", ".svg")


@dataclass(frozen=True)
class HistoryRow:
    """One spec (``signal is None``) or one signal of one recorded run."""

    started_utc: str
    model_version: str
    spec: str
    spec_name: str
    signal: str | None
    phi: float | None
    #: λ values keyed by characteristic name (empty on a spec row).
    lambdas: Mapping[str, float | None]
    lag_s: float | None
    passed: bool | None
    #: 95 % intervals (low, high) by field (``"phi"`` or a characteristic name), where recorded.
    intervals: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def interval(self, name: str) -> tuple[float, float] | None:
        return self.intervals.get(name)

    def value(self, field: str) -> float | None:
        """``"phi"``, ``"lag_s"`` or a characteristic name."""
        if field == "phi":
            return self.phi
        if field == "lag_s":
            return self.lag_s
        return self.lambdas.get(field)

    def to_dict(self) -> dict[str, Any]:
        return {
            "started_utc": self.started_utc,
            "model_version": self.model_version,
            "spec": self.spec,
            "spec_name": self.spec_name,
            "signal": self.signal,
            "phi": self.phi,
            "lambdas": dict(self.lambdas) if self.lambdas else None,
            "lag_s": self.lag_s,
            "passed": self.passed,
        }


def _matches_spec(spec: RecordedSpec, pattern: str | None) -> bool:
    if pattern is None:
        return True
    key, name = spec.key, spec.name or ""
    return pattern in (key, name) or fnmatchcase(key, pattern) or fnmatchcase(name, pattern)


def _matches_signal(signal: RecordedSignal, pattern: str) -> bool:
    return pattern in (signal.path, signal.name) or fnmatchcase(signal.path, pattern)


def history_table(
    runs: Iterable[RecordedRun], spec: str | None = None, signal: str | None = None
) -> list[HistoryRow]:
    """Rows of Φ (and, when ``signal`` is given, λ1–λ7 and lag) over the recorded runs.

    ``spec`` and ``signal`` match exactly (spec path or name; signal path or name) or as a
    shell glob (``"E_batt/*"``). Without ``signal`` there is one row per spec and run.
    Rows are ordered by run time, then spec, then signal.
    """
    rows: list[HistoryRow] = []
    for run in sorted(runs, key=lambda r: r.started_utc or ""):
        for spec_result in run.specs:
            if not _matches_spec(spec_result, spec):
                continue
            spec_row = HistoryRow(
                started_utc=run.started_utc or "",
                model_version=run.model_version or "unknown",
                spec=spec_result.key,
                spec_name=spec_result.title,
                signal=None,
                phi=spec_result.phi,
                lambdas={},
                lag_s=None,
                passed=spec_result.passed,
                intervals={}
                if spec_result.phi_interval is None
                else {"phi": spec_result.phi_interval},
            )
            if signal is None:
                rows.append(spec_row)
                continue
            for sig in spec_result.signals:
                if not _matches_signal(sig, signal):
                    continue
                rows.append(
                    replace(
                        spec_row,
                        signal=sig.path,
                        lambdas=sig.lambdas,
                        lag_s=sig.lag_s,
                        passed=sig.passed,
                        intervals={**spec_row.intervals, **sig.intervals},
                    )
                )
    return rows


def characteristic_names(rows: Sequence[HistoryRow]) -> list[str]:
    """Every characteristic any of ``rows`` carries, in report order."""
    return order_names(name for row in rows for name in row.lambdas)


def row_series(rows: Sequence[HistoryRow]) -> dict[tuple[str, str | None], list[HistoryRow]]:
    """Group rows into one time series per (spec, signal)."""
    series: dict[tuple[str, str | None], list[HistoryRow]] = {}
    for row in rows:
        series.setdefault((row.spec, row.signal), []).append(row)
    return series


def _fmt(value: float | None, digits: int = 4) -> str:
    return "—" if value is None else f"{value:.{digits}f}"


def render_history_table(rows: Sequence[HistoryRow]) -> str:
    """A plain-text table of the rows, aligned in columns."""
    if not rows:
        return "(no recorded runs match)"
    with_signals = any(row.signal is not None for row in rows)
    names = characteristic_names(rows)
    header = ["time (UTC)", "model version", "spec"]
    if with_signals:
        header += ["signal"]
    header += ["Φ"]
    if with_signals:
        header += [describe(n).symbol for n in names] + ["lag s"]
    header += ["passed"]
    table = [header]
    for row in rows:
        cells = [row.started_utc[:19].replace("T", " "), row.model_version, row.spec]
        if with_signals:
            cells.append(row.signal or "")
        cells.append(_fmt(row.phi))
        if with_signals:
            cells += [_fmt(row.lambdas.get(n)) for n in names] + [_fmt(row.lag_s, 2)]
        cells.append({True: "yes", False: "NO", None: "—"}[row.passed])
        table.append(cells)
    widths = [max(len(line[i]) for line in table) for i in range(len(header))]
    lines = [
        "  ".join(cell.ljust(w) for cell, w in zip(line, widths, strict=True)).rstrip()
        for line in table
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


# -- step detection -------------------------------------------------------------------------


@dataclass(frozen=True)
class Step:
    """A lasting change of level in a series.

    ``index`` is the first position at the new level; ``before``/``after`` are the medians of
    the neighbouring segments; ``score`` is the size in units of the series' noise.
    """

    index: int
    before: float
    after: float
    score: float
    regression: bool

    @property
    def size(self) -> float:
        return self.after - self.before


def noise_sigma(values: npt.ArrayLike) -> float:
    """Robust noise level: the MAD of first differences, scaled to σ of white noise.

    Differences cancel the level, so a step adds a single outlier that the median ignores.
    """
    x = np.asarray(values, dtype=float)
    if x.size < 2:
        return 0.0
    d = np.diff(x)
    return float(_MAD_TO_SIGMA * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def detect_steps(
    series: Sequence[float | None] | npt.ArrayLike,
    *,
    min_size: float,
    threshold: float = 5.0,
    min_segment: int = 2,
    higher_is_better: bool = True,
    intervals: Sequence[tuple[float, float] | None] | None = None,
) -> list[Step]:
    """Find lasting level changes in ``series`` by binary segmentation.

    Each segment is split where the two sides' means differ most in units of their standard
    error (a two-sample statistic with the noise σ from :func:`noise_sigma`); a split is kept
    when that statistic reaches ``threshold`` *and* the medians of the two sides differ by at
    least ``min_size``; both halves are then searched again. Non-finite and ``None`` values
    are skipped; indices refer to the original series.

    Parameters
    ----------
    min_size:
        Smallest change worth reporting, in the series' unit (e.g. 0.01 for Φ).
    threshold:
        Required size of the change relative to the noise; 5 keeps flat noisy series of a few
        hundred points free of false steps.
    min_segment:
        Fewest points on each side of a step, so that a single outlier is not a step.
    higher_is_better:
        Whether a drop (True, for Φ and λ) or a rise (False, for errors) is a regression.
    intervals:
        Each point's 95 % interval (low, high), or None where unknown. A step is then kept
        only when it is beyond noise: larger than the median half-widths of the intervals on
        its two sides together, so that the typical intervals before and after do not overlap.
    """
    if not math.isfinite(min_size) or min_size < 0:
        raise HistoryError(f"min_size must be a finite number ≥ 0 (got {min_size!r})")
    if min_segment < 1:
        raise HistoryError(f"min_segment must be ≥ 1 (got {min_segment!r})")
    raw = np.array(
        [np.nan if v is None else v for v in np.asarray(series, dtype=object).ravel()],
        dtype=float,
    )
    positions = np.flatnonzero(np.isfinite(raw))
    x = raw[positions]
    if x.size < 2 * min_segment:
        return []
    scale = max(1.0, float(np.max(np.abs(x))))
    # A perfectly repeatable series has zero noise; a floor keeps the statistic finite.
    sigma = max(noise_sigma(x), 1e-12 * scale)
    splits: list[int] = []
    pending = [(0, int(x.size))]
    while pending:
        start, stop = pending.pop()
        split = _best_split(x[start:stop], sigma, min_segment, threshold, min_size)
        if split is not None:
            splits.append(start + split)
            pending += [(start, start + split), (start + split, stop)]
    splits.sort()
    bounds = [0, *splits, int(x.size)]
    steps = []
    for k in range(1, len(bounds) - 1):
        before = float(np.median(x[bounds[k - 1] : bounds[k]]))
        after = float(np.median(x[bounds[k] : bounds[k + 1]]))
        n_left = bounds[k] - bounds[k - 1]
        n_right = bounds[k + 1] - bounds[k]
        score = abs(after - before) / (sigma * math.sqrt(1 / n_left + 1 / n_right))
        worse = after < before if higher_is_better else after > before
        left = positions[bounds[k - 1] : bounds[k]]
        right = positions[bounds[k] : bounds[k + 1]]
        if intervals is not None and not _beyond_noise(after - before, intervals, left, right):
            continue
        steps.append(Step(int(positions[bounds[k]]), before, after, score, worse))
    return steps


def _beyond_noise(
    change: float,
    intervals: Sequence[tuple[float, float] | None],
    left: npt.NDArray[np.intp],
    right: npt.NDArray[np.intp],
) -> bool:
    """Whether a change exceeds the typical half-widths of the intervals on both sides."""

    def half_width(where: npt.NDArray[np.intp]) -> float | None:
        widths = [
            (bounds[1] - bounds[0]) / 2.0
            for i in where.tolist()
            if i < len(intervals) and (bounds := intervals[i]) is not None
        ]
        return float(np.median(widths)) if widths else None

    before, after = half_width(left), half_width(right)
    if before is None or after is None:
        return True  # no interval recorded: the series' own noise decides
    return abs(change) > before + after


def _best_split(
    x: npt.NDArray[np.float64], sigma: float, min_segment: int, threshold: float, min_size: float
) -> int | None:
    n = int(x.size)
    if n < 2 * min_segment:
        return None
    cumulative = np.concatenate([[0.0], np.cumsum(x)])
    k = np.arange(min_segment, n - min_segment + 1)
    left = cumulative[k] / k
    right = (cumulative[n] - cumulative[k]) / (n - k)
    stat = np.abs(left - right) / (sigma * np.sqrt(1.0 / k + 1.0 / (n - k)))
    best = int(k[int(np.argmax(stat))])
    if float(np.max(stat)) < threshold:
        return None
    if abs(float(np.median(x[:best])) - float(np.median(x[best:]))) < max(min_size, 0.0):
        return None
    return best


# -- plot -----------------------------------------------------------------------------------


def plot_history(rows: Sequence[HistoryRow], path: Path | str) -> Path:
    """Plot Φ (and λ1–λ7 of signal rows) over runs into a PNG or SVG file.

    Uses matplotlib's object API with the Agg canvas, imported here, so no global pyplot
    state is touched and no figure outlives the call.
    """
    path = Path(path)
    if path.suffix.lower() not in _PLOT_SUFFIXES:
        raise HistoryError(
            f"cannot plot to {path.suffix or 'a file without suffix'!r}",
            file=str(path),
            hint="name the file *.png or *.svg",
        )
    if not rows:
        raise HistoryError("nothing to plot: no recorded runs match", file=str(path))
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        from ..errors import MissingExtraError

        raise MissingExtraError.for_extra("--plot", "plot", "matplotlib") from None

    runs = sorted({(row.started_utc, row.model_version) for row in rows})
    x_of = {run: i for i, run in enumerate(runs)}
    with_signals = any(row.signal is not None for row in rows)
    figure = Figure(figsize=(10, 7 if with_signals else 4), layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(2 if with_signals else 1, 1, sharex=True, squeeze=False)[:, 0]
    # Signal rows repeat their spec's Φ; plot each spec's Φ once per run.
    phi: dict[str, dict[int, float]] = {}
    for row in rows:
        phi.setdefault(row.spec, {})[x_of[(row.started_utc, row.model_version)]] = (
            np.nan if row.phi is None else row.phi
        )
    for spec, points in phi.items():
        xs = sorted(points)
        axes[0].plot(xs, [points[x] for x in xs], "o-", label=plot_text(spec))
    if with_signals:
        for (_spec, signal), series in row_series(rows).items():
            xs = [x_of[(r.started_utc, r.model_version)] for r in series]
            for name in characteristic_names(series):
                ys = [r.value(name) for r in series]
                axes[1].plot(
                    xs,
                    [np.nan if y is None else y for y in ys],
                    ".-",
                    label=f"{plot_text(signal)} {describe(name).symbol}",
                )
        axes[1].set_ylabel("λ")
        axes[1].legend(fontsize="x-small", ncol=2, loc="best")
    axes[0].set_ylabel("Φ")
    axes[0].legend(fontsize="small", loc="best")
    axes[-1].set_xticks(range(len(runs)))
    axes[-1].set_xticklabels([plot_text(version) for _, version in runs], rotation=45, ha="right")
    axes[-1].set_xlabel("model version (oldest first)")
    buffer = io.BytesIO()
    figure.savefig(buffer, format=path.suffix.lower().lstrip("."))
    write_atomic(path, buffer.getvalue())
    return path

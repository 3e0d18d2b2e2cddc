"""Per-signal plots as inline SVG, drawn straight from the figure data.

A report can hold hundreds of signals. Drawing each through matplotlib costs a few tenths of a
second; writing the few polygons of these plots as SVG text costs milliseconds and stays sharp
at any zoom. What makes the text small:

* the time-axis plots hold one point per pixel column of the plot (the envelope of the buckets
  that fall in it: min of the minima, max of the maxima, so no spike is lost);
* coordinates are whole units of the viewBox, about one pixel each at the page's width, and a
  run of equal steps is written as one step (the same line, drawn the same);
* path data seen before on the page (a model input equal to its measurement, the same recording
  in two specs) is drawn by reference to the first copy (:class:`PathShare`);
* styling lives in the page's CSS (classes ``hv-*``), not in every element.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.registry import order_names
from ..results.recorded import RecordedPoint
from ..results.spec_result import SignalResult
from .model import CHARACTERISTIC_COLOURS, SHORT_LABELS, is_finite_number

__all__ = ["Panel", "PathShare", "column_envelope", "history_svg", "nice_ticks", "signal_svg"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# Shorter path data is cheaper written inline than as a shared element and a reference.
_SHARED_MIN = 200

# Writing numbers is most of a plot's time; the steps of a path are small integers, so their
# text comes from a table (a sign or a space first, so the tokens join without separators).
_TOKENS_MAX = 2048
_TOKENS = tuple(str(v) if v < 0 else f" {v}" for v in range(-_TOKENS_MAX, _TOKENS_MAX + 1))


def _esc(text: object) -> str:
    return html.escape(str(text), quote=True)


def nice_ticks(low: float, high: float, count: int = 5) -> list[float]:
    """Round tick values (1, 2, 2.5 or 5 × 10^k apart) covering [low, high]."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return []
    if high < low:
        low, high = high, low
    if high == low:
        return [low]
    raw = (high - low) / max(1, count)
    magnitude = 10.0 ** math.floor(math.log10(raw))
    step = next(m * magnitude for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * magnitude >= raw)
    first = math.ceil(low / step - 1e-9) * step
    ticks = []
    value = first
    while value <= high + step * 1e-9:
        ticks.append(0.0 if abs(value) < step * 1e-9 else value)
        value += step
    return ticks


def _label(value: float, ticks: Sequence[float]) -> str:
    """Tick label with as many decimals as the spacing needs, at most 5 significant digits."""
    if len(ticks) > 1:
        step = abs(ticks[1] - ticks[0])
        biggest = max(abs(t) for t in ticks)
        if biggest >= 1e5 or (biggest and biggest < 1e-3):
            return f"{value:.3g}"
        decimals = max(0, -math.floor(math.log10(step) + 1e-9)) if step else 0
        if step and abs(step * 10**decimals - round(step * 10**decimals)) > 1e-6:
            decimals += 1
        return f"{value:.{decimals}f}"
    return f"{value:.4g}"


def _array(values: object) -> FloatArray:
    """A float array of ``values`` (``None`` → NaN), or an empty one if they are not numbers."""
    if not isinstance(values, Sequence) or isinstance(values, str):
        return np.empty(0, dtype=np.float64)
    try:
        out = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        out = np.array([v if is_finite_number(v) else np.nan for v in values], dtype=np.float64)
    return out if out.ndim == 1 else np.empty(0, dtype=np.float64)


def _column_runs(time: FloatArray, x0: float, x1: float, columns: int) -> tuple[IntArray, IntArray]:
    """Pixel column of each run of buckets that fall in one column, and where each run starts.

    ``time`` must be sorted; bucket ``i`` falls in the column of its mid time on [x0, x1].
    """
    scale = columns / (x1 - x0)
    column = np.clip(np.floor((time - x0) * scale), 0, columns - 1).astype(np.int64)
    starts = np.flatnonzero(np.concatenate([[True], column[1:] != column[:-1]]))
    return column[starts], starts.astype(np.int64)


def _sorted_finite(time: FloatArray, *series: FloatArray) -> tuple[FloatArray, ...]:
    """``time`` and ``series`` without non-finite times, in time order (hand-written results
    may hold either)."""
    keep = np.isfinite(time)
    if not keep.all():
        time, series = time[keep], tuple(s[keep] for s in series)
    if time.size > 1 and bool((np.diff(time) < 0).any()):
        order = np.argsort(time, kind="stable")
        time, series = time[order], tuple(s[order] for s in series)
    return (time, *series)


def column_envelope(
    time: FloatArray, lows: FloatArray, highs: FloatArray, x0: float, x1: float, columns: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The envelope of buckets on [x0, x1] merged into ``columns`` pixel columns.

    Returns the centre of every column that holds a bucket (in columns from the left edge) and
    the min of its minima and the max of its maxima, so a spike one sample wide keeps its
    extreme. NaN in ``lows`` or ``highs`` is ignored unless a whole column is NaN.
    """
    time, lows, highs = _sorted_finite(time, lows, highs)
    if time.size == 0:
        empty = np.empty(0, dtype=np.float64)
        return empty, empty, empty
    column, starts = _column_runs(time, x0, x1, columns)
    return (
        column.astype(np.float64) + 0.5,
        np.fmin.reduceat(lows, starts),
        np.fmax.reduceat(highs, starts),
    )


def _column_means(
    time: FloatArray, values: FloatArray, weights: FloatArray, x0: float, x1: float, columns: int
) -> tuple[FloatArray, FloatArray]:
    """Weighted means per pixel column, so drawn areas keep their fractions."""
    time, values, weights = _sorted_finite(time, values, weights)
    if time.size == 0:
        empty = np.empty(0, dtype=np.float64)
        return empty, empty
    column, starts = _column_runs(time, x0, x1, columns)
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.add.reduceat(values * weights, starts) / np.add.reduceat(weights, starts)
    return column.astype(np.float64) + 0.5, means


class PathShare:
    """Path data drawn once per page: a later plot with the same data refers to the first copy.

    The first copy carries an id and takes its style from a wrapping group, so that a ``<use>``
    of another class styles its copy by inheritance (an element inside a ``<use>`` keeps the
    classes of the original). Ids are numbered in drawing order, so equal input gives equal
    pages.
    """

    def __init__(self) -> None:
        self._ids: dict[str, str] = {}

    def element(self, css: str, d: str) -> str:
        if len(d) < _SHARED_MIN:
            return f'<path class="{css}" d="{d}"/>'
        found = self._ids.get(d)
        if found is not None:
            return f'<use class="{css}" href="#{found}"/>'
        ident = self._ids[d] = f"hvp{len(self._ids)}"
        return f'<g class="{css}"><path id="{ident}" d="{d}"/></g>'


class Panel:
    """A rectangle of the SVG with linear data→pixel scales and its own axes."""

    def __init__(
        self,
        x: float,
        y: float,
        width: float,
        height: float,
        x_range: tuple[float, float],
        y_range: tuple[float, float],
    ) -> None:
        self.x, self.y, self.width, self.height = x, y, width, height
        self.x0, self.x1 = _widen(*x_range)
        self.y0, self.y1 = _widen(*y_range)

    def px(self, values: FloatArray | float) -> Any:
        # Plain floats (ticks, marks) skip numpy, whose per-call cost is many times the sum.
        scale = self.width / (self.x1 - self.x0)
        if isinstance(values, (float, int)):
            return self.x + (values - self.x0) * scale
        return self.x + (np.asarray(values) - self.x0) * scale

    def py(self, values: FloatArray | float) -> Any:
        scale = self.height / (self.y1 - self.y0)
        if isinstance(values, (float, int)):
            return self.y + self.height - (values - self.y0) * scale
        return self.y + self.height - (np.asarray(values) - self.y0) * scale

    def frame(
        self,
        parts: list[str],
        *,
        x_label: str | None,
        y_label: str | None,
        x_ticks: bool = True,
        y_ticks: Sequence[float] | None = None,
        share: PathShare | None = None,
    ) -> None:
        xt = nice_ticks(self.x0, self.x1, max(4, int(self.width // 110)))
        yt = list(y_ticks) if y_ticks is not None else nice_ticks(self.y0, self.y1, 4)
        grid = []
        for t in xt:
            if self.x0 <= t <= self.x1:
                grid.append(f"M{float(self.px(t)):.1f} {self.y:.1f}v{self.height:.1f}")
        for t in yt:
            if self.y0 <= t <= self.y1:
                grid.append(f"M{self.x:.1f} {float(self.py(t)):.1f}h{self.width:.1f}")
        parts.append(_draw("hv-grid", "".join(grid), share))
        parts.append(
            f'<rect class="hv-frame" x="{self.x:.1f}" y="{self.y:.1f}" '
            f'width="{self.width:.1f}" height="{self.height:.1f}"/>'
        )
        if x_ticks:
            for t in xt:
                if self.x0 <= t <= self.x1:
                    parts.append(
                        f'<text class="hv-tick" x="{float(self.px(t)):.1f}" '
                        f'y="{self.y + self.height + 13:.1f}" text-anchor="middle">'
                        f"{_label(t, xt)}</text>"
                    )
        for t in yt:
            if self.y0 <= t <= self.y1:
                parts.append(
                    f'<text class="hv-tick" x="{self.x - 5:.1f}" y="{float(self.py(t)) + 3.5:.1f}" '
                    f'text-anchor="end">{_label(t, yt)}</text>'
                )
        if x_label:
            parts.append(
                f'<text class="hv-axis" x="{self.x + self.width / 2:.1f}" '
                f'y="{self.y + self.height + 29:.1f}" text-anchor="middle">{_esc(x_label)}</text>'
            )
        if y_label:
            cx, cy = self.x - 48, self.y + self.height / 2
            parts.append(
                f'<text class="hv-axis" x="{cx:.1f}" y="{cy:.1f}" text-anchor="middle" '
                f'transform="rotate(-90 {cx:.1f} {cy:.1f})">{_esc(y_label)}</text>'
            )

    @property
    def columns(self) -> int:
        """Pixel columns of the panel (one viewBox unit is about one pixel on the page)."""
        return max(1, round(self.width))

    def column_x(self, centres: FloatArray) -> FloatArray:
        """x of column centres as :func:`column_envelope` gives them."""
        return self.x + centres * (self.width / self.columns)

    def band(self, xs: FloatArray, lows: FloatArray, highs: FloatArray) -> str | None:
        """Path data of the area between ``lows`` and ``highs`` at pixel positions ``xs``."""
        keep = np.isfinite(xs) & np.isfinite(lows) & np.isfinite(highs)
        xs, lows, highs = xs[keep], lows[keep], highs[keep]
        if xs.size == 0:
            return None
        return (
            _path(np.concatenate([xs, xs[::-1]]), self.py(np.concatenate([highs, lows[::-1]])))
            + "Z"
        )

    def line(self, xs: FloatArray, ys: FloatArray) -> str | None:
        """Path data of the line through (``xs``, ``ys``) in data units."""
        keep = np.isfinite(xs) & np.isfinite(ys)
        if not keep.any():
            return None
        return _path(self.px(xs[keep]), self.py(ys[keep]))

    def clip(self, ident: str) -> str:
        return (
            f'<clipPath id="{ident}"><rect x="{self.x:.1f}" y="{self.y:.1f}" '
            f'width="{self.width:.1f}" height="{self.height:.1f}"/></clipPath>'
        )


def _widen(low: float, high: float) -> tuple[float, float]:
    if not (math.isfinite(low) and math.isfinite(high)):
        return 0.0, 1.0
    if high - low <= 1e-12 * max(1.0, abs(low), abs(high)):
        pad = max(abs(low) * 0.05, 0.5)
        return low - pad, high + pad
    return low, high


def _path(xs: FloatArray, ys: FloatArray) -> str:
    """Path data in whole units: an absolute moveto, then relative linetos.

    One unit is about one pixel of the page, which is what the plots resolve. Rounding the
    absolute positions first and differencing the integers keeps the steps exact, so no error
    accumulates along the path. A point that rounds onto the one before is left out, and a run
    of steps in one direction becomes one step: the line drawn is the same, and a flat or
    straight stretch costs a few characters however long it is.
    """
    # floor(v + 0.5), not rint: rint rounds halves to even, and column centres sit on halves.
    points = np.floor(np.column_stack([xs, ys]) + 0.5).astype(np.int64)
    head = f"M{points[0, 0]} {points[0, 1]}"
    steps = np.diff(points, axis=0)
    steps = steps[(steps != 0).any(axis=1)]
    if steps.shape[0] > 1:
        before, after = steps[:-1], steps[1:]
        onward = (before[:, 0] * after[:, 1] == before[:, 1] * after[:, 0]) & (
            (before * after).sum(axis=1) > 0
        )
        starts = np.flatnonzero(np.concatenate([[True], ~onward]))
        steps = np.add.reduceat(steps, starts, axis=0)
    if steps.shape[0] == 0:
        return head
    flat = steps.ravel()
    if int(np.abs(flat).max()) <= _TOKENS_MAX:
        body = "".join(map(_TOKENS.__getitem__, (flat + _TOKENS_MAX).tolist()))
    else:
        body = " ".join(map(str, flat.tolist())).replace(" -", "-")
    # "3-2" and "3 2" both separate two numbers in path syntax.
    return f"{head}l{body.lstrip()}"


def _range(*arrays: FloatArray, pad: float = 0.05) -> tuple[float, float]:
    finite = [a[np.isfinite(a)] for a in arrays]
    finite = [a for a in finite if a.size]
    if not finite:
        return 0.0, 1.0
    low = min(float(a.min()) for a in finite)
    high = max(float(a.max()) for a in finite)
    span = high - low
    return low - pad * span, high + pad * span


def _draw(css: str, d: str | None, share: PathShare | None = None) -> str:
    """A path element of class ``css`` for path data ``d`` (nothing for ``None``)."""
    if d is None:
        return ""
    if share is None:
        return f'<path class="{css}" d="{d}"/>'
    return share.element(css, d)


def signal_svg(signal: SignalResult, ident: str, share: PathShare | None = None) -> str | None:
    """Overlay, residual and derivative match along time; correlation curve; error histogram.

    ``ident`` makes the SVG's clip-path ids unique within the page; ``share`` draws path data
    the page already holds by reference (one per page; by default only within this plot).
    Returns ``None`` when the signal carries no figure data.
    """
    share = share if share is not None else PathShare()
    data = signal.figures
    if not isinstance(data, Mapping) or not isinstance(data.get("overlay"), Mapping):
        return None
    overlay = data["overlay"]
    time = _array(overlay.get("time"))
    if time.size == 0:
        return None
    series = {k: _array(overlay.get(k)) for k in ("ref_min", "ref_max", "sim_min", "sim_max")}
    series.update({k: _array(overlay.get(k)) for k in ("res_min", "res_max")})
    if any(v.shape != time.shape for v in series.values()):
        return None
    unit = str(signal.unit or "")
    suffix = f" [{unit}]" if unit else ""
    ident = "".join(ch if ch.isalnum() else "-" for ch in ident)

    width, height = 1240, 520
    left, right_of_time = 78, 850
    time_range = _time_range(data, time)
    parts: list[str] = []
    defs: list[str] = []

    # Overlay: reference and simulated envelopes, one point per pixel column.
    columns = right_of_time - left
    x0, x1 = _widen(*time_range)
    c_ref, ref_lo, ref_hi = column_envelope(
        time, series["ref_min"], series["ref_max"], x0, x1, columns
    )
    c_sim, sim_lo, sim_hi = column_envelope(
        time, series["sim_min"], series["sim_max"], x0, x1, columns
    )
    c_res, res_lo, res_hi = column_envelope(
        time, series["res_min"], series["res_max"], x0, x1, columns
    )
    ov = Panel(
        left, 28, right_of_time - left, 222, time_range, _range(ref_lo, ref_hi, sim_lo, sim_hi)
    )
    defs.append(ov.clip(f"{ident}-ov"))
    ov.frame(
        parts,
        x_label=None,
        y_label=f"{signal.name or ''}{suffix}",
        x_ticks=False,
        share=share,
    )
    parts.append(f'<g clip-path="url(#{ident}-ov)">')
    parts.extend(_hot_spans(signal, ov))
    parts.append(_draw("hv-ref", ov.band(ov.column_x(c_ref), ref_lo, ref_hi), share))
    parts.append(_draw("hv-sim", ov.band(ov.column_x(c_sim), sim_lo, sim_hi), share))
    parts.append("</g>")
    parts.append(
        f'<g class="hv-legend"><rect class="hv-ref" x="{left + 8}" y="12" width="14" height="8"/>'
        f'<text x="{left + 27}" y="20">reference (measured)</text>'
        f'<rect class="hv-sim" x="{left + 168}" y="12" width="14" height="8"/>'
        f'<text x="{left + 187}" y="20">simulated</text>'
        f'<text x="{right_of_time}" y="20" text-anchor="end" class="hv-note">min/max per pixel '
        f"column of {_esc(_bucket_note(data, c_ref.size))}</text></g>"
    )

    # Residual beneath, on the same time axis.
    res = Panel(
        left, 266, right_of_time - left, 100, time_range, _range(res_lo, res_hi, np.zeros(1))
    )
    defs.append(res.clip(f"{ident}-res"))
    res.frame(parts, x_label=None, y_label=f"residual{suffix}", x_ticks=False, share=share)
    parts.append(f'<g clip-path="url(#{ident}-res)">')
    parts.append(_draw("hv-zero", res.line(np.array(time_range), np.zeros(2)), share))
    parts.append(_draw("hv-res", res.band(res.column_x(c_res), res_lo, res_hi), share))
    parts.append("</g>")

    # Derivative directionality match along time (paper Fig. 7).
    der = Panel(left, 382, right_of_time - left, 80, time_range, (0.0, 1.0))
    derivative = data.get("derivative") if isinstance(data.get("derivative"), Mapping) else {}
    match = _array(derivative.get("match")) if derivative else np.empty(0)
    parts.append(
        f'<rect class="hv-mismatch" x="{der.x:.1f}" y="{der.y:.1f}" width="{der.width:.1f}" '
        f'height="{der.height:.1f}"/>'
    )
    if match.shape == time.shape:
        weights = _array(overlay.get("count"))
        if weights.shape != time.shape:
            weights = np.ones_like(time)
        c_m, m_mean = _column_means(time, match, weights, x0, x1, columns)
        parts.append(
            _draw("hv-match", der.band(der.column_x(c_m), np.zeros_like(m_mean), m_mean), share)
        )
    der.frame(parts, x_label="time [s]", y_label="direction", y_ticks=[0.0, 0.5, 1.0], share=share)
    fraction = derivative.get("fraction") if derivative else None
    if is_finite_number(fraction):
        y = float(der.py(float(fraction)))
        parts.append(f'<path class="hv-dash" d="M{der.x:.1f} {y:.1f}h{der.width:.1f}"/>')
        parts.append(
            f'<text class="hv-tag" x="{der.x + der.width - 4:.1f}" '
            f'y="{der.y + der.height - 6:.1f}" '
            f'text-anchor="end">λ2 = {float(fraction):.3f} of samples match in sign</text>'
        )

    # Cross-correlation (paper Fig. 5).
    correlation = data.get("correlation") if isinstance(data.get("correlation"), Mapping) else None
    if correlation:
        lags = _array(correlation.get("lag_s"))
        values = _array(correlation.get("value"))
        if lags.size and lags.shape == values.shape:
            peak = correlation.get("peak")
            peak_lag = correlation.get("peak_lag_s")
            xc = Panel(
                938, 46, 280, 170, _range(lags, pad=0.0), _range(values, np.array([1.0]), pad=0.08)
            )
            defs.append(xc.clip(f"{ident}-xc"))
            xc.frame(
                parts,
                x_label="lag [s] (negative: model lags)",
                y_label="mean-removed correlation",
                share=share,
            )
            parts.append(f'<g clip-path="url(#{ident}-xc)">')
            if xc.x0 <= 0.0 <= xc.x1:
                parts.append(_draw("hv-zero", xc.line(np.zeros(2), np.array([xc.y0, xc.y1]))))
            parts.append(_draw("hv-xc", xc.line(lags, values), share))
            parts.append("</g>")
            if is_finite_number(peak) and is_finite_number(peak_lag):
                px, py = float(xc.px(float(peak_lag))), float(xc.py(float(peak)))
                parts.append(f'<circle class="hv-peak" cx="{px:.1f}" cy="{py:.1f}" r="4"/>')
                parts.append(
                    f'<text class="hv-title" x="{xc.x:.1f}" y="{xc.y - 22:.1f}">cross-correlation'
                    f"</text>"
                    f'<text class="hv-tag" x="{xc.x:.1f}" y="{xc.y - 8:.1f}">peak '
                    f"{float(peak):.4f} at {float(peak_lag):+.3g} s"
                    + (
                        f" · {float(correlation['zero_lag']):.4f} at 0 s"
                        if is_finite_number(correlation.get("zero_lag"))
                        else ""
                    )
                    + (" · on the search edge" if correlation.get("at_bound") else "")
                    + "</text>"
                )

    # Error histogram with its CDF (paper Fig. 9).
    histogram = data.get("histogram") if isinstance(data.get("histogram"), Mapping) else None
    if histogram:
        edges = _array(histogram.get("edges"))
        counts = _array(histogram.get("counts"))
        cdf = _array(histogram.get("cdf"))
        if edges.size == counts.size + 1 and counts.size:
            hi_count = float(np.nanmax(counts)) if counts.size else 1.0
            hs = Panel(938, 292, 250, 170, _range(edges, pad=0.0), (0.0, hi_count * 1.08 or 1.0))
            hs.frame(parts, x_label=f"error y_ref − y_sim{suffix}", y_label="samples", share=share)
            parts.append(_draw("hv-bar", _bars(hs, edges, counts), share))
            if hs.x0 <= 0.0 <= hs.x1:
                parts.append(_draw("hv-zero", hs.line(np.zeros(2), np.array([hs.y0, hs.y1]))))
            if cdf.shape == counts.shape:
                cdf_panel = Panel(hs.x, hs.y, hs.width, hs.height, (hs.x0, hs.x1), (0.0, 1.0))
                steps_x = np.repeat(edges, 2)[1:-1]
                steps_y = np.repeat(cdf, 2)
                parts.append(_draw("hv-cdf", cdf_panel.line(steps_x, steps_y), share))
                for t in (0.0, 0.5, 1.0):
                    parts.append(
                        f'<text class="hv-tick" x="{hs.x + hs.width + 5:.1f}" '
                        f'y="{float(cdf_panel.py(t)) + 3.5:.1f}">{t:g}</text>'
                    )
                cx, cy = hs.x + hs.width + 34, hs.y + hs.height / 2
                parts.append(
                    f'<text class="hv-axis" x="{cx:.1f}" y="{cy:.1f}" text-anchor="middle" '
                    f'transform="rotate(90 {cx:.1f} {cy:.1f})">cumulative fraction</text>'
                )
            # Two lines, as the cross-correlation's: one would run past the plot's right edge.
            parts.append(
                f'<text class="hv-title" x="{hs.x:.1f}" y="{hs.y - 22:.1f}">error histogram</text>'
                f'<text class="hv-tag" x="{hs.x:.1f}" y="{hs.y - 8:.1f}">'
                "line: cumulative fraction (right axis)</text>"
            )

    title = f"{signal.path or signal.name or 'signal'}: measured vs simulated"
    return (
        f'<svg class="hv-plot" viewBox="0 0 {width} {height}" role="img">'
        f"<title>{_esc(title)}</title>"
        f"<defs>{''.join(defs)}</defs>{''.join(parts)}</svg>"
    )


def _bars(panel: Panel, edges: FloatArray, counts: FloatArray) -> str | None:
    """Path data of the histogram's bars in whole units, each bin with samples at least one
    unit tall: a tail bin of a few samples among thousands is an extreme worth seeing."""
    if not np.isfinite(edges).all():
        return None
    counts = np.where(np.isfinite(counts) & (counts > 0), counts, 0.0)
    x = np.floor(panel.px(edges) + 0.5).astype(np.int64)
    base = math.floor(panel.y + panel.height + 0.5)
    heights = np.maximum(base - np.floor(panel.py(counts) + 0.5).astype(np.int64), 1)
    drawn = "".join(
        f"M{x0} {base}v-{h}h{x1 - x0}v{h}Z"
        for x0, x1, h, c in zip(
            x[:-1].tolist(), x[1:].tolist(), heights.tolist(), counts.tolist(), strict=True
        )
        if c > 0
    )
    return drawn or None


def _hot_spans(signal: SignalResult, panel: Panel) -> list[str]:
    """The windows where the error concentrates (``local:``), shaded behind the overlay."""
    if signal.local is None:
        return []
    spans = (signal.local.concentration or {}).get("spans_s") or []
    out = []
    for a, b in spans:
        x0, x1 = float(panel.px(float(a))), float(panel.px(float(b)))
        out.append(
            f'<rect class="hv-hot" x="{x0:.1f}" y="{panel.y}" width="{max(x1 - x0, 1):.1f}" '
            f'height="{panel.height}"><title>error concentrates here: {float(a):.0f}–'
            f"{float(b):.0f} s</title></rect>"
        )
    return out


def _time_range(data: Mapping[str, Any], time: FloatArray) -> tuple[float, float]:
    """The record's full span (bucket mid-times would clip half a bucket at each end)."""
    start, dt, n = data.get("start_s"), data.get("dt"), data.get("n_samples")
    if is_finite_number(start) and is_finite_number(dt) and is_finite_number(n) and int(n) > 1:
        first = float(start)
        return first, first + (int(n) - 1) * float(dt)
    return float(np.nanmin(time)), float(np.nanmax(time))


def _bucket_note(data: Mapping[str, Any], drawn: int) -> str:
    n = data.get("n_samples")
    if is_finite_number(n) and int(n) > drawn > 0:
        return f"{int(n) / drawn:.3g} samples ({int(n)} in all)"
    return "1 sample"


def history_svg(history: Sequence[RecordedPoint]) -> str | None:
    """λ1…λ7 (thin, coloured) and Φ (thick, dark) over recorded versions."""
    entries = list(history)
    if not entries:
        return None
    lines: dict[str, FloatArray] = {}
    keyed = [h.lambdas for h in entries]
    for name in order_names(n for values_of in keyed for n in values_of):
        values = []
        for values_of in keyed:
            value = values_of.get(name)
            values.append(float(value) if is_finite_number(value) else np.nan)
        lines[name] = np.array(values, dtype=np.float64)
    phi = np.array([np.nan if h.phi is None else h.phi for h in entries], dtype=np.float64)
    x = np.arange(len(entries), dtype=np.float64)
    width, height = 720, 230
    panel = Panel(
        64, 16, 520, 170, (-0.3, max(len(entries) - 0.7, 0.3)), _range(phi, *lines.values())
    )
    parts: list[str] = []
    panel.frame(parts, x_label=None, y_label="value", x_ticks=False)
    for xi, h in zip(x, entries, strict=True):
        parts.append(
            f'<text class="hv-tick" x="{float(panel.px(xi)):.1f}" '
            f'y="{panel.y + panel.height + 14:.1f}" '
            f'text-anchor="middle">{_esc(h.version)}</text>'
        )
    legend_y = panel.y + 6
    for name, ys in lines.items():
        if np.isfinite(ys).any():
            colour = CHARACTERISTIC_COLOURS[name]
            parts.append(
                f'<path class="hv-hist-line" stroke="{colour}" '
                f'd="{_path(panel.px(x[np.isfinite(ys)]), panel.py(ys[np.isfinite(ys)]))}"/>'
            )
            parts.append(
                f'<rect x="{panel.x + panel.width + 16}" y="{legend_y:.1f}" width="12" height="4" '
                f'fill="{colour}"/><text class="hv-tick" x="{panel.x + panel.width + 32}" '
                f'y="{legend_y + 5:.1f}">{SHORT_LABELS[name]}</text>'
            )
            legend_y += 17
    if np.isfinite(phi).any():
        keep = np.isfinite(phi)
        parts.append(f'<path class="hv-phi" d="{_path(panel.px(x[keep]), panel.py(phi[keep]))}"/>')
        for xi, yi in zip(x[keep], phi[keep], strict=True):
            parts.append(
                f'<circle class="hv-phi-dot" cx="{float(panel.px(xi)):.1f}" '
                f'cy="{float(panel.py(yi)):.1f}" r="3.5"/>'
            )
        parts.append(
            f'<rect x="{panel.x + panel.width + 16}" y="{legend_y:.1f}" width="12" height="4" '
            f'fill="#1f2328"/><text class="hv-tick" x="{panel.x + panel.width + 32}" '
            f'y="{legend_y + 5:.1f}">Φ</text>'
        )
    return (
        f'<svg class="hv-plot hv-small" viewBox="0 0 {width} {height}" role="img">'
        "<title>characteristics over recorded versions"
        f"</title>{''.join(parts)}</svg>"
    )

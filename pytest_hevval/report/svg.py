"""Per-signal plots as inline SVG, drawn straight from the figure data.

A report can hold hundreds of signals. Drawing each through matplotlib costs a few tenths of a
second; writing the few polygons of these plots as SVG text costs milliseconds, stays sharp at
any zoom, and is no larger than a PNG once the envelope is merged down to one bucket per pixel
(min of the minima, max of the maxima, so no spike is lost). Styling lives in the page's CSS
(classes ``hv-*``), not in every element.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from ..core.registry import order_names
from .model import CHARACTERISTIC_COLOURS, SHORT_LABELS, _lambdas, is_finite_number

__all__ = ["history_svg", "nice_ticks", "signal_svg"]

FloatArray = npt.NDArray[np.float64]


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


def _merge(
    time: FloatArray, lows: FloatArray, highs: FloatArray, buckets: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Envelope merged into at most ``buckets`` buckets (exact: min of minima, max of maxima)."""
    n = time.shape[0]
    if n <= buckets:
        return time, lows, highs
    starts = (np.arange(buckets, dtype=np.int64) * n // buckets).astype(np.intp)
    ends = np.append(starts[1:], n) - 1
    return (
        (time[starts] + time[ends]) / 2.0,
        np.fmin.reduceat(lows, starts),
        np.fmax.reduceat(highs, starts),
    )


def _merge_mean(
    time: FloatArray, values: FloatArray, weights: FloatArray, buckets: int
) -> tuple[FloatArray, FloatArray]:
    """Weighted means over at most ``buckets`` buckets, so drawn areas keep their fractions."""
    n = time.shape[0]
    if n <= buckets:
        return time, values
    starts = (np.arange(buckets, dtype=np.int64) * n // buckets).astype(np.intp)
    ends = np.append(starts[1:], n) - 1
    means = np.add.reduceat(values * weights, starts) / np.add.reduceat(weights, starts)
    return (time[starts] + time[ends]) / 2.0, means


class _Panel:
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
        return self.x + (np.asarray(values) - self.x0) * (self.width / (self.x1 - self.x0))

    def py(self, values: FloatArray | float) -> Any:
        return (
            self.y
            + self.height
            - (np.asarray(values) - self.y0) * (self.height / (self.y1 - self.y0))
        )

    def frame(
        self,
        parts: list[str],
        *,
        x_label: str | None,
        y_label: str | None,
        x_ticks: bool = True,
        y_ticks: Sequence[float] | None = None,
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
        parts.append(f'<path class="hv-grid" d="{"".join(grid)}"/>')
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

    def band(self, time: FloatArray, lows: FloatArray, highs: FloatArray, css: str) -> str:
        keep = np.isfinite(time) & np.isfinite(lows) & np.isfinite(highs)
        time, lows, highs = time[keep], lows[keep], highs[keep]
        if time.size == 0:
            return ""
        xs = self.px(np.concatenate([time, time[::-1]]))
        ys = self.py(np.concatenate([highs, lows[::-1]]))
        return f'<path class="{css}" d="{_path(xs, ys)}Z"/>'

    def line(self, xs: FloatArray, ys: FloatArray, css: str) -> str:
        keep = np.isfinite(xs) & np.isfinite(ys)
        if not keep.any():
            return ""
        return f'<path class="{css}" d="{_path(self.px(xs[keep]), self.py(ys[keep]))}"/>'

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
    """Path data in tenths of a unit: an absolute moveto, then relative linetos.

    Rounding the absolute positions first and differencing the integers keeps the deltas exact,
    so no error accumulates along the path; short deltas make the text about a third smaller
    than absolute coordinates.
    """
    tenths = np.rint(np.column_stack([xs, ys]) * 10.0).astype(np.int64)
    head = f"M{tenths[0, 0] / 10} {tenths[0, 1] / 10}"
    if tenths.shape[0] == 1:
        return head.replace(".0", "")
    deltas = (np.diff(tenths, axis=0).ravel() / 10.0).tolist()
    body = " ".join(map(str, deltas)) + " "
    # "1.0 " → "1 " and "3 -2" → "3-2": both are valid SVG path syntax.
    return f"{head.replace('.0', '')}l{body.replace('.0 ', ' ').replace(' -', '-').strip()}"


def _range(*arrays: FloatArray, pad: float = 0.05) -> tuple[float, float]:
    finite = [a[np.isfinite(a)] for a in arrays]
    finite = [a for a in finite if a.size]
    if not finite:
        return 0.0, 1.0
    low = min(float(a.min()) for a in finite)
    high = max(float(a.max()) for a in finite)
    span = high - low
    return low - pad * span, high + pad * span


def signal_svg(signal: Mapping[str, Any], ident: str) -> str | None:
    """Overlay, residual and derivative match along time; correlation curve; error histogram.

    ``ident`` makes the SVG's clip-path ids unique within the page. Returns ``None`` when the
    signal carries no figure data.
    """
    data = signal.get("figures")
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
    unit = str(signal.get("unit") or "")
    suffix = f" [{unit}]" if unit else ""
    ident = "".join(ch if ch.isalnum() else "-" for ch in ident)

    width, height = 1240, 520
    left, right_of_time = 78, 850
    time_range = _time_range(data, time)
    parts: list[str] = []
    defs: list[str] = []

    # Overlay: reference and simulated envelopes.
    buckets = int(right_of_time - left)
    t_ref, ref_lo, ref_hi = _merge(time, series["ref_min"], series["ref_max"], buckets)
    t_sim, sim_lo, sim_hi = _merge(time, series["sim_min"], series["sim_max"], buckets)
    t_res, res_lo, res_hi = _merge(time, series["res_min"], series["res_max"], buckets)
    ov = _Panel(
        left, 28, right_of_time - left, 222, time_range, _range(ref_lo, ref_hi, sim_lo, sim_hi)
    )
    defs.append(ov.clip(f"{ident}-ov"))
    ov.frame(parts, x_label=None, y_label=f"{signal.get('name') or ''}{suffix}", x_ticks=False)
    parts.append(f'<g clip-path="url(#{ident}-ov)">')
    parts.extend(_hot_spans(signal, ov))
    parts.append(ov.band(t_ref, ref_lo, ref_hi, "hv-ref"))
    parts.append(ov.band(t_sim, sim_lo, sim_hi, "hv-sim"))
    parts.append("</g>")
    parts.append(
        f'<g class="hv-legend"><rect class="hv-ref" x="{left + 8}" y="12" width="14" height="8"/>'
        f'<text x="{left + 27}" y="20">reference (measured)</text>'
        f'<rect class="hv-sim" x="{left + 168}" y="12" width="14" height="8"/>'
        f'<text x="{left + 187}" y="20">simulated</text>'
        f'<text x="{right_of_time}" y="20" text-anchor="end" class="hv-note">min/max per '
        f"bucket of {_esc(_bucket_note(data, time.size, t_ref.size))}</text></g>"
    )

    # Residual beneath, on the same time axis.
    res = _Panel(
        left, 266, right_of_time - left, 100, time_range, _range(res_lo, res_hi, np.zeros(1))
    )
    defs.append(res.clip(f"{ident}-res"))
    res.frame(parts, x_label=None, y_label=f"residual{suffix}", x_ticks=False)
    parts.append(f'<g clip-path="url(#{ident}-res)">')
    parts.append(res.line(np.array(time_range), np.zeros(2), "hv-zero"))
    parts.append(res.band(t_res, res_lo, res_hi, "hv-res"))
    parts.append("</g>")

    # Derivative directionality match along time (paper Fig. 7).
    der = _Panel(left, 382, right_of_time - left, 80, time_range, (0.0, 1.0))
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
        t_m, m_mean = _merge_mean(time, match, weights, buckets)
        parts.append(der.band(t_m, np.zeros_like(m_mean), m_mean, "hv-match"))
    der.frame(parts, x_label="time [s]", y_label="direction", y_ticks=[0.0, 0.5, 1.0])
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
            xc = _Panel(
                938, 46, 280, 170, _range(lags, pad=0.0), _range(values, np.array([1.0]), pad=0.08)
            )
            defs.append(xc.clip(f"{ident}-xc"))
            xc.frame(parts, x_label="lag [s] (negative: model lags)", y_label="correlation")
            parts.append(f'<g clip-path="url(#{ident}-xc)">')
            if xc.x0 <= 0.0 <= xc.x1:
                parts.append(xc.line(np.zeros(2), np.array([xc.y0, xc.y1]), "hv-zero"))
            parts.append(xc.line(lags, values, "hv-xc"))
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
            hs = _Panel(938, 292, 250, 170, _range(edges, pad=0.0), (0.0, hi_count * 1.08 or 1.0))
            hs.frame(parts, x_label=f"error y_ref − y_sim{suffix}", y_label="samples")
            bars = []
            for a, b, c in zip(edges[:-1], edges[1:], counts, strict=True):
                if c > 0:
                    x0, x1 = float(hs.px(a)), float(hs.px(b))
                    top, base = float(hs.py(c)), hs.y + hs.height
                    bars.append(f"M{x0:.1f} {base:.1f}V{top:.1f}H{x1:.1f}V{base:.1f}Z")
            parts.append(f'<path class="hv-bar" d="{"".join(bars)}"/>')
            if hs.x0 <= 0.0 <= hs.x1:
                parts.append(hs.line(np.zeros(2), np.array([hs.y0, hs.y1]), "hv-zero"))
            if cdf.shape == counts.shape:
                cdf_panel = _Panel(hs.x, hs.y, hs.width, hs.height, (hs.x0, hs.x1), (0.0, 1.0))
                steps_x = np.repeat(edges, 2)[1:-1]
                steps_y = np.repeat(cdf, 2)
                parts.append(cdf_panel.line(steps_x, steps_y, "hv-cdf"))
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
            parts.append(
                f'<text class="hv-title" x="{hs.x:.1f}" y="{hs.y - 8:.1f}">error histogram '
                "and cumulative distribution</text>"
            )

    title = f"{signal.get('path') or signal.get('name') or 'signal'}: measured vs simulated"
    return (
        f'<svg class="hv-plot" viewBox="0 0 {width} {height}" role="img">'
        f"<title>{_esc(title)}</title>"
        f"<defs>{''.join(defs)}</defs>{''.join(parts)}</svg>"
    )


def _hot_spans(signal: Mapping[str, Any], panel: _Panel) -> list[str]:
    """The windows where the error concentrates (``local:``), shaded behind the overlay."""
    local = signal.get("local")
    if not isinstance(local, Mapping):
        return []
    spans = (local.get("concentration") or {}).get("spans_s") or []
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


def _bucket_note(data: Mapping[str, Any], buckets: int, drawn: int) -> str:
    n = data.get("n_samples")
    if is_finite_number(n) and int(n) > drawn:
        return f"{int(n) / drawn:.3g} samples ({int(n)} in all)"
    return "1 sample"


def history_svg(history: Sequence[Mapping[str, Any]]) -> str | None:
    """λ1…λ7 (thin, coloured) and Φ (thick, dark) over recorded versions."""
    entries = [h for h in history if isinstance(h, Mapping)]
    if not entries:
        return None
    lines: dict[str, FloatArray] = {}
    keyed = [_lambdas(h) for h in entries]
    for name in order_names(n for values_of in keyed for n in values_of):
        values = []
        for values_of in keyed:
            value = values_of.get(name)
            values.append(float(value) if is_finite_number(value) else np.nan)
        lines[name] = np.array(values, dtype=np.float64)
    phi = np.array(
        [h["phi"] if is_finite_number(h.get("phi")) else np.nan for h in entries], dtype=np.float64
    )
    x = np.arange(len(entries), dtype=np.float64)
    width, height = 720, 230
    panel = _Panel(
        64, 16, 520, 170, (-0.3, max(len(entries) - 0.7, 0.3)), _range(phi, *lines.values())
    )
    parts: list[str] = []
    panel.frame(parts, x_label=None, y_label="value", x_ticks=False)
    for xi, h in zip(x, entries, strict=True):
        parts.append(
            f'<text class="hv-tick" x="{float(panel.px(xi)):.1f}" '
            f'y="{panel.y + panel.height + 14:.1f}" '
            f'text-anchor="middle">{_esc(h.get("version", int(xi) + 1))}</text>'
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

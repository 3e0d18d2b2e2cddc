"""Where and when, drawn: λ per time window as a strip, λ, Φ and coverage per region cell.

Plain SVG from the typed result (the signal's
:class:`~pytest_hevval.results.local_tables.LocalResult`) and the spec's grid of cells, like
:mod:`.svg`; every piece of text is escaped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from html import escape
from typing import Any

from ..core.registry import describe, order_names
from ..results.codec import number_or_nan
from ..results.spec_facts import RegionGrid
from ..results.spec_result import SignalResult

__all__ = ["coverage_svg", "heatmap_svg", "timeline_svg"]

_LOW, _MID, _HIGH = (215, 48, 31), (254, 224, 139), (26, 152, 80)
_UNJUDGED = "#e5e5e5"


def _mix(a: tuple[int, int, int], b: tuple[int, int, int], t: float) -> str:
    r, g, bl = (round(x + (y - x) * t) for x, y in zip(a, b, strict=True))
    return f"#{r:02x}{g:02x}{bl:02x}"


def _colour(value: float, low: float) -> str:
    """Red at ``low``, yellow half-way, green at 1."""
    if not math.isfinite(value):
        return _UNJUDGED
    t = 1.0 if low >= 1.0 else min(1.0, max(0.0, (value - low) / (1.0 - low)))
    return _mix(_LOW, _MID, 2 * t) if t < 0.5 else _mix(_MID, _HIGH, 2 * t - 1)


def _low(values: Sequence[float], threshold: float | None) -> float:
    finite = [v for v in values if math.isfinite(v)]
    candidates = [*finite, *([threshold] if threshold is not None else [])]
    low = min(candidates) if candidates else 0.0
    return min(low, 0.99)


def timeline_svg(signal: SignalResult) -> str | None:
    """One strip per characteristic: λ of every time window as colour; misses outlined."""
    local = signal.local
    if local is None:
        return None
    windows = local.windows
    spans = [(float(a), float(b)) for a, b in local.spans_s]
    lambdas = windows.lambdas
    if not spans or not lambdas:
        return None
    names = order_names(lambdas)
    missed: dict[str, set[str]] = {}
    for failure in signal.local_failures:
        if failure.scope == "windows":
            missed.setdefault(failure.characteristic, set()).update(failure.where)
    left, right, row, top = 150, 850, 16, 18
    start, stop = spans[0][0], spans[-1][1]
    scale = (right - left) / max(stop - start, 1e-12)
    height = top + row * len(names) + 24
    parts = [
        f'<svg class="hv-local" viewBox="0 0 {right + 20} {height}" width="100%" '
        f'role="img" aria-label="characteristics per time window">'
    ]
    labels = list(windows.labels)
    for i, name in enumerate(names):
        values = [number_or_nan(v) for v in lambdas[name]]
        low = _low(values, None)
        y = top + i * row
        title = escape(describe(name).title)
        parts.append(f'<text x="{left - 6}" y="{y + row - 4}" text-anchor="end">{title}</text>')
        for k, (a, b) in enumerate(spans):
            x = left + (a - start) * scale
            w = max((b - a) * scale, 0.5)
            label = labels[k] if k < len(labels) else f"{a:.0f}–{b:.0f} s"
            outline = ' stroke="#000" stroke-width="1.5"' if label in missed.get(name, ()) else ""
            value = values[k] if k < len(values) else math.nan
            text = "not judged" if not math.isfinite(value) else f"{value:.4f}"
            parts.append(
                f'<rect x="{x:.1f}" y="{y}" width="{w:.1f}" height="{row - 2}" '
                f'fill="{_colour(value, low)}"{outline}><title>{escape(label)}: {title} '
                f"{text}</title></rect>"
            )
    axis_y = top + row * len(names) + 14
    parts.append(f'<text x="{left}" y="{axis_y}">{start:.0f} s</text>')
    parts.append(f'<text x="{right}" y="{axis_y}" text-anchor="end">{stop:.0f} s</text>')
    parts.append(
        f'<text x="{(left + right) / 2}" y="{axis_y}" text-anchor="middle" class="hv-note">'
        "λ per window: red low, green 1; black outline: window missed its gate</text>"
    )
    parts.append("</svg>")
    return "".join(parts)


def _grid_geometry(region: RegionGrid) -> tuple[int, int]:
    shape = [int(v) for v in region.shape]
    return (shape[0], shape[1]) if len(shape) == 2 else (shape[0] if shape else 0, 1)


def _grid_svg(
    region: RegionGrid,
    fills: Sequence[str],
    texts: Sequence[str],
    tips: Sequence[str],
    title: str,
    outlined: set[int] | None = None,
) -> str | None:
    columns, rows = _grid_geometry(region)
    if columns * rows == 0 or len(fills) != columns * rows:
        return None
    edges = region.edges
    by = [str(v) for v in region.by]
    cell_w, cell_h, left, top = 58, 24, 120, 28
    width = left + cell_w * columns + 20
    height = top + cell_h * rows + 44
    parts = [
        f'<svg class="hv-local" viewBox="0 0 {width} {height}" width="{width}" role="img" '
        f'aria-label="{escape(title)}">',
        f'<text x="{left}" y="16" class="hv-title">{escape(title)}</text>',
    ]
    for flat in range(columns * rows):
        # C order: the first variable runs along x, the second (if any) up the y axis.
        col, row = (flat // rows, flat % rows) if rows > 1 else (flat, 0)
        x = left + col * cell_w
        y = top + (rows - 1 - row) * cell_h
        outline = ' stroke="#000" stroke-width="2"' if outlined and flat in outlined else ""
        parts.append(
            f'<rect x="{x}" y="{y}" width="{cell_w - 2}" height="{cell_h - 2}" '
            f'fill="{fills[flat]}"{outline}><title>{escape(tips[flat])}</title></rect>'
            f'<text x="{x + cell_w / 2 - 1}" y="{y + cell_h / 2 + 3}" text-anchor="middle" '
            f'class="hv-cell">{escape(texts[flat])}</text>'
        )
    if edges:
        xs = edges[0]
        for k, edge in enumerate(xs):
            parts.append(
                f'<text x="{left + k * cell_w - 1}" y="{top + rows * cell_h + 12}" '
                f'text-anchor="middle" class="hv-note">{number_or_nan(edge):.4g}</text>'
            )
        parts.append(
            f'<text x="{left + columns * cell_w / 2}" y="{top + rows * cell_h + 30}" '
            f'text-anchor="middle">{escape(by[0] if by else "")}</text>'
        )
    if len(edges) == 2:
        for k, edge in enumerate(edges[1]):
            parts.append(
                f'<text x="{left - 4}" y="{top + (rows - k) * cell_h + 3}" text-anchor="end" '
                f'class="hv-note">{number_or_nan(edge):.4g}</text>'
            )
        parts.append(
            f'<text x="12" y="{top + rows * cell_h / 2}" '
            f'transform="rotate(-90 12 {top + rows * cell_h / 2})" text-anchor="middle">'
            f"{escape(by[1] if len(by) > 1 else '')}</text>"
        )
    parts.append("</svg>")
    return "".join(parts)


def heatmap_svg(
    region: RegionGrid,
    values: Sequence[Any],
    title: str,
    threshold: float | None = None,
    missed: Sequence[str] = (),
) -> str | None:
    """A value in [0, 1] per cell (λ or Φ); cells with too few samples grey, misses outlined."""
    counts = [int(c) for c in region.counts]
    labels = [str(v) for v in region.labels]
    minimum = int(region.min_samples)
    numbers = [number_or_nan(v) for v in values]
    if len(numbers) != len(counts):
        return None
    judged = [v if c >= minimum else math.nan for v, c in zip(numbers, counts, strict=True)]
    low = _low(judged, threshold)
    fills = [_colour(v, low) for v in judged]
    texts = [
        f"{v:.3f}" if math.isfinite(v) else ("—" if c == 0 else f"n={c}")
        for v, c in zip(judged, counts, strict=True)
    ]
    tips = [
        f"{label}: {text} ({count} samples)"
        for label, text, count in zip(labels, texts, counts, strict=True)
    ]
    outlined = {k for k, label in enumerate(labels) if label in set(missed)}
    return _grid_svg(region, fills, texts, tips, title, outlined)


def coverage_svg(region: RegionGrid) -> str | None:
    """Samples per cell; cells of the declared space never visited are left white."""
    counts = [int(c) for c in region.counts]
    labels = [str(v) for v in region.labels]
    if not counts:
        return None
    top = max(max(counts), 1)
    fills = [
        "#ffffff"
        if c == 0
        else _mix((222, 235, 247), (8, 81, 156), math.log1p(c) / math.log1p(top))
        for c in counts
    ]
    texts = [str(c) if c else "never" for c in counts]
    tips = [f"{label}: {c} samples" for label, c in zip(labels, counts, strict=True)]
    return _grid_svg(region, fills, texts, tips, "coverage: samples per cell")

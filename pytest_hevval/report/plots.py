"""The behavioural glyph plot (paper Fig. 10) as inline SVG, drawn from result dicts only.

There is one per spec. It is written as SVG text like the per-signal plots
(:mod:`pytest_hevval.report.svg`): drawing it through matplotlib and encoding a PNG took about a
third of a second per spec, most of the time an HTML report took, and gave a bitmap of some
30 KB that blurs when zoomed. Sizes follow the former figure (pt at 100 dpi), so the glyphs
look as they did.
"""

from __future__ import annotations

import math
from html import escape

from ..core.registry import order_names
from ..results.spec_result import SpecResult
from .model import CHARACTERISTIC_COLOURS, LABELS, SHORT_LABELS, GlyphPoint, glyph_points
from .svg import Panel, PathShare, nice_ticks

__all__ = ["glyph_plot"]

# Glyph area (pt²) by tree level: level 1 largest, as in the paper's Fig. 10.
_LEVEL_SIZE = {1: 340.0, 2: 170.0, 3: 85.0}
_MIN_SIZE = 45.0
_ANNOTATE = 6
_PX_PER_PT = 100.0 / 72.0

# The former figure's 1280 × 480 px, most of it axes, the legend on the right.
_WIDTH = 1280
_PLOT = (60.0, 10.0, 1010.0, 430.0)  # x, y, width, height of the axes
_LEGEND_ROW = 22.0


def _radius(area_pt2: float) -> float:
    """Radius in px of a marker of ``area_pt2`` (matplotlib's ``s``: the square of its size)."""
    return math.sqrt(area_pt2) / 2.0 * _PX_PER_PT


def _level_radius(level: int) -> float:
    return _radius(_LEVEL_SIZE.get(level, _MIN_SIZE))


def _circle(x: float, y: float, r: float, css: str, fill: str, tip: str = "") -> str:
    title = f"<title>{escape(tip)}</title>" if tip else ""
    end = f">{title}</circle>" if title else "/>"
    return f'<circle class="{css}" cx="{x:.1f}" cy="{y:.1f}" r="{r:.1f}" fill="{fill}"{end}'


def glyph_plot(spec: SpecResult, share: PathShare | None = None) -> str | None:
    """Paper Fig. 10 for one spec: x = λ, y = α·β, size by level, fill by characteristic.

    Glyphs sharing a weight are spread over a thin band (a fixed offset per characteristic)
    so that none hides another; failing glyphs get a red ring and the worst few a label. Every
    glyph names its signal, characteristic and value on hover. ``share`` draws path data the
    page already holds by reference (the grid of equal axes). Returns ``None`` when the spec
    has no λ to plot.
    """
    points = glyph_points(spec)
    if not points:
        return None
    weights = [p.weight for p in points]
    y_span = max(max(weights) - min(weights), 0.2 * max(max(weights), 1e-9))
    band = 0.012 * y_span

    def y_of(p: GlyphPoint) -> float:
        return p.weight + (p.index - 4) * band

    x_min = min(p.value for p in points)
    left = max(0.0, min(x_min - 0.05 * max(1.0 - x_min, 0.02), 0.98))
    right = 1.0 + 0.03 * (1.0 - left)
    low, high = min(weights), max(weights)
    pad = max(0.15 * (high - low), 6 * band, 0.1 * high, 0.05)
    panel = Panel(*_PLOT, (left, right), (max(0.0, low - pad), high + pad))
    parts: list[str] = []
    panel.frame(
        parts,
        x_label="λ value (1 = perfect match)",
        y_label="weight α·β",
        y_ticks=nice_ticks(panel.y0, panel.y1, 7),
        share=share,
    )

    # Largest glyphs first so that small (deep-level) glyphs stay visible on top.
    for p in sorted(points, key=lambda p: (p.level, p.index)):
        parts.append(
            _circle(
                float(panel.px(p.value)),
                float(panel.py(y_of(p))),
                _level_radius(p.level),
                "hv-gl fail" if p.status == "fail" else "hv-gl",
                CHARACTERISTIC_COLOURS[p.characteristic],
                f"{p.signal} · {SHORT_LABELS[p.characteristic]} "
                f"{LABELS[p.characteristic]} {p.value:.4f}",
            )
        )

    worst = sorted(points, key=lambda p: (p.status != "fail", p.value))[:_ANNOTATE]
    middle = (left + right) / 2
    for rank, p in enumerate(worst):
        # Labels point inwards (left of right-hand glyphs, above bottom-row glyphs) and are
        # staggered so that neighbours do not print over each other.
        to_left = p.value > middle
        upwards = p.weight < high or low == high
        x, y = float(panel.px(p.value)), float(panel.py(y_of(p)))
        rise = (20 + 14 * (rank % 3)) * _PX_PER_PT
        tx = x + (-16 if to_left else 16) * _PX_PER_PT
        ty = y - rise if upwards else y + rise
        parts.append(f'<path class="hv-lead" d="M{x:.1f} {y:.1f}L{tx:.1f} {ty:.1f}"/>')
        parts.append(
            f'<text class="hv-tag{" fail" if p.status == "fail" else ""}" x="{tx:.1f}" '
            f'y="{ty - 3 if upwards else ty + 9:.1f}" '
            f'text-anchor="{"end" if to_left else "start"}">{escape(p.signal)} · '
            f"{SHORT_LABELS[p.characteristic]} {p.value:.3f}</text>"
        )

    legend, bottom = _legend(points, panel.x + panel.width + 16, panel.y + 4)
    parts.append(legend)
    height = math.ceil(max(panel.y + panel.height + 40, bottom + 8))
    name = spec.name or spec.spec
    return (
        f'<svg class="hv-glyph" viewBox="0 0 {_WIDTH} {height}" role="img">'
        f"<title>behavioural glyph plot of {escape(name)}</title>{''.join(parts)}</svg>"
    )


def _legend(points: list[GlyphPoint], x: float, top: float) -> tuple[str, float]:
    """The legend (characteristics, levels, the failure ring) and the y of its bottom."""
    rows: list[tuple[float, str, str, str]] = [
        (_radius(64.0), "hv-gl", CHARACTERISTIC_COLOURS[n], f"{SHORT_LABELS[n]} {LABELS[n]}")
        for n in order_names(p.characteristic for p in points)
    ]
    rows += [
        (_level_radius(level), "hv-gkey", "#ffffff", f"level {level}")
        for level in sorted({p.level for p in points})
    ]
    rows.append((_radius(81.0), "hv-gl fail", "#ffffff", "below threshold"))
    parts = ['<g class="hv-legend">']
    y = top
    for r, css, fill, label in rows:
        step = max(_LEGEND_ROW, 2 * r + 4)
        centre = y + step / 2
        parts.append(_circle(x + 13, centre, r, css, fill))
        parts.append(f'<text x="{x + 32:.1f}" y="{centre + 4:.1f}">{escape(label)}</text>')
        y += step
    parts.append("</g>")
    return "".join(parts), y

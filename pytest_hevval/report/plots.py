"""The behavioural glyph plot (paper Fig. 10), drawn with matplotlib from result dicts only.

There is one per spec, so its cost does not grow with the number of signals (the per-signal
plots are inline SVG, see :mod:`pytest_hevval.report.svg`). matplotlib is imported on first
use. The figure is a :class:`matplotlib.figure.Figure` on an Agg canvas, not pyplot, so nothing
global is touched and nothing stays open; it is cleared once encoded. The PNG is
palette-quantised (Pillow ships with matplotlib): the plot has few colours, so this cuts its
size several times at no visible cost.
"""

from __future__ import annotations

import base64
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..core.registry import order_names
from ..errors import MissingExtraError
from .model import (
    CHARACTERISTIC_COLOURS,
    LABELS,
    SHORT_LABELS,
    GlyphPoint,
    glyph_points,
)

__all__ = ["Png", "glyph_plot"]

REFERENCE = "#1f2328"
SIMULATED = "#0969da"
RESIDUAL = "#8250df"
PASS = "#1a7f37"
FAIL = "#cf222e"
GRID = "#d0d7de"

# Glyph area (pt²) by tree level: level 1 largest, as in the paper's Fig. 10.
_LEVEL_SIZE = {1: 340.0, 2: 170.0, 3: 85.0}
_MIN_SIZE = 45.0
_ANNOTATE = 6
_DPI = 100


def _matplotlib() -> Any:
    try:
        import matplotlib
    except ImportError as exc:
        raise MissingExtraError.for_extra("the HTML report", "html", "matplotlib") from exc
    return matplotlib


def _new_figure(width: float, height: float) -> Any:
    _matplotlib()
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _style(ax: Any) -> None:
    ax.grid(True, color=GRID, linewidth=0.6)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    ax.tick_params(labelsize=8, colors="#57606a")


@dataclass(frozen=True)
class Png:
    """A base64-encoded PNG with its size in pixels (so the page reserves its box at once)."""

    data: str
    width: int
    height: int


def _encode(fig: Any) -> Png:
    """``fig`` as PNG; the figure is cleared afterwards."""
    try:
        fig.canvas.draw()
        width, height = fig.canvas.get_width_height()
        rgba = fig.canvas.buffer_rgba()
        buffer = io.BytesIO()
        try:
            from PIL import Image
        except ImportError:  # pragma: no cover - Pillow is a matplotlib dependency
            fig.savefig(buffer, format="png", dpi=_DPI)
        else:
            image = Image.frombuffer("RGBA", (width, height), rgba, "raw")
            image.convert("RGB").quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(
                buffer, format="PNG", optimize=False, compress_level=6
            )
        return Png(base64.b64encode(buffer.getvalue()).decode("ascii"), int(width), int(height))
    finally:
        fig.clear()


def glyph_plot(spec: Mapping[str, Any]) -> Png | None:
    """Paper Fig. 10 for one spec as PNG: x = λ, y = α·β, size by level, fill by λ.

    Glyphs sharing a weight are spread over a thin band (a fixed offset per characteristic)
    so that none hides another; failing glyphs get a red ring and the worst few a label.
    """
    points = glyph_points(spec)
    if not points:
        return None
    fig = _new_figure(12.8, 4.8)
    ax = fig.add_subplot()
    _style(ax)
    weights = [p.weight for p in points]
    y_span = max(max(weights) - min(weights), 0.2 * max(max(weights), 1e-9))
    band = 0.012 * y_span

    def y_of(p: GlyphPoint) -> float:
        return p.weight + (p.index - 4) * band

    # Largest glyphs first so that small (deep-level) glyphs stay visible on top.
    ordered = sorted(points, key=lambda p: (p.level, p.index))
    for level in sorted({p.level for p in ordered}):
        group = [p for p in ordered if p.level == level]
        ax.scatter(
            [p.value for p in group],
            [y_of(p) for p in group],
            s=_LEVEL_SIZE.get(level, _MIN_SIZE),
            c=[CHARACTERISTIC_COLOURS[p.characteristic] for p in group],
            edgecolors=[FAIL if p.status == "fail" else "#1f2328" for p in group],
            linewidths=[2.2 if p.status == "fail" else 0.5 for p in group],
            alpha=0.85,
            zorder=3 + level,
        )
    worst = sorted(points, key=lambda p: (p.status != "fail", p.value))[:_ANNOTATE]
    x_min = min(p.value for p in points)
    left = max(0.0, min(x_min - 0.05 * max(1.0 - x_min, 0.02), 0.98))
    right = 1.0 + 0.03 * (1.0 - left)
    ax.set_xlim(left, right)
    low, high = min(weights), max(weights)
    middle = (left + right) / 2
    for rank, p in enumerate(worst):
        # Labels point inwards (left of right-hand glyphs, above bottom-row glyphs) and are
        # staggered so that neighbours do not print over each other.
        to_left = p.value > middle
        upwards = p.weight < high or low == high
        rise = 20 + 14 * (rank % 3)
        ax.annotate(
            f"{p.signal} · {SHORT_LABELS[p.characteristic]} {p.value:.3f}",
            (p.value, y_of(p)),
            xytext=(-16 if to_left else 16, rise if upwards else -rise),
            textcoords="offset points",
            ha="right" if to_left else "left",
            va="bottom" if upwards else "top",
            fontsize=8,
            color=FAIL if p.status == "fail" else "#1f2328",
            arrowprops={"arrowstyle": "-", "color": "#57606a", "linewidth": 0.7},
            zorder=10,
        )
    pad = max(0.15 * (high - low), 6 * band, 0.1 * high, 0.05)
    ax.set_ylim(max(0.0, low - pad), high + pad)
    ax.set_xlabel("λ value (1 = perfect match)", fontsize=9)
    ax.set_ylabel("weight α·β", fontsize=9)

    from matplotlib.lines import Line2D

    handles = [
        Line2D(
            [],
            [],
            marker="o",
            linestyle="",
            markersize=8,
            markerfacecolor=CHARACTERISTIC_COLOURS[name],
            markeredgecolor="#1f2328",
            label=f"{SHORT_LABELS[name]} {LABELS[name]}",
        )
        for name in order_names(p.characteristic for p in points)
    ]
    for level in sorted({p.level for p in points}):
        handles.append(
            Line2D(
                [],
                [],
                marker="o",
                linestyle="",
                markersize=math.sqrt(_LEVEL_SIZE.get(level, _MIN_SIZE)),
                markerfacecolor="#ffffff",
                markeredgecolor="#57606a",
                label=f"level {level}",
            )
        )
    handles.append(
        Line2D(
            [],
            [],
            marker="o",
            linestyle="",
            markersize=9,
            markerfacecolor="#ffffff",
            markeredgecolor=FAIL,
            markeredgewidth=2.2,
            label="below threshold",
        )
    )
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=8,
        frameon=False,
        labelspacing=1.1,
        borderpad=0.8,
    )
    return _encode(fig)

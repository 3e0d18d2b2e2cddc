"""The self-contained HTML report: one file, CSS inline, no scripts, no external URLs.

Every plot is inline SVG written directly from the typed results: the glyph plot by
:mod:`pytest_hevval.report.plots`, the per-signal plots from the figure data by
:mod:`pytest_hevval.report.svg`, the local ones by :mod:`pytest_hevval.report.local_svg`.
Path data is drawn once per page and referred to where it repeats (:class:`svg.PathShare`).

jinja2 (autoescaping on) is imported on first use. Everything the page shows
comes from the results via :mod:`pytest_hevval.report.model`, the same view-model as the
JSON and Markdown reports; each signal's diagnosis and trend from its :class:`.SignalPanels`.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from .. import __version__
from ..core.registry import describe
from ..errors import MissingExtraError
from ..results.local_tables import LocalFailure
from ..results.spec_facts import RegionGrid
from ..results.spec_result import SignalResult, SpecResult
from ..results.verdict import RunVerdict
from . import local_svg, model, plots, svg
from .panels import SignalPanels
from .sentences import lag_text, local_failure_text
from .terminal import runtime_of, runtime_text
from .trace import trace_rows

__all__ = ["render_html"]

_TEMPLATE = "report.html.j2"


def _fmt(value: object, digits: int = 4) -> str:
    if not model.is_finite_number(value):
        return "—"
    number = float(value)
    if number != 0 and (abs(number) >= 1e6 or abs(number) < 10 ** -(digits - 1)):
        return f"{number:.{digits - 1}e}"
    return f"{number:.{digits}f}"


def _fmt_g(value: object, digits: int = 4) -> str:
    if not model.is_finite_number(value):
        return "—"
    return f"{float(value):.{digits}g}"


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-") or "x"


def _percent(value: object) -> float:
    """Position of a [0, 1] value on a bar, in percent."""
    if not model.is_finite_number(value):
        return 0.0
    return max(0.0, min(100.0, 100.0 * float(value)))


def _signal_view(
    result: SpecResult,
    spec_index: int,
    signal: SignalResult,
    anchors: Mapping[str, str],
    share: svg.PathShare,
    panels: SignalPanels,
    region_grid: RegionGrid | None,
) -> dict[str, Any]:
    diagnosis = panels.diagnosis(result, signal)
    history = panels.history(result, signal)
    failed = not signal.passed
    origins = [str(o) for o in signal.origins]
    path = signal.path or signal.name
    errors = signal.characteristics.as_dict()
    return {
        "signal": signal,
        "errors": errors,
        "path": path,
        "anchor": anchors.get(path, f"spec{spec_index}-{_slug(path)}"),
        "cells": model.cells(signal),
        "standard_metrics": model.standard_metric_rows(signal),
        "measurement": model.measurement_lines(signal),
        "lag": lag_text(errors),
        "failed": failed,
        "is_origin": failed and signal.origin,
        "origins": [(o, anchors.get(o)) for o in origins if o != path],
        "margin": model.margin(signal),
        "plot": svg.signal_svg(signal, f"{spec_index}-{anchors.get(path, path)}", share),
        "diagnosis": diagnosis if isinstance(diagnosis, Mapping) else None,
        "history": svg.history_svg(history) if history is not None else None,
        **_local_view(signal, region_grid),
    }


def _local_view(signal: SignalResult, region_grid: RegionGrid | None) -> dict[str, Any]:
    """Where and when: the window strip, phase and condition tables, the cell heat maps."""
    local = signal.local
    if local is None:
        return {"local": None}
    regions = local.regions
    maps: list[str] = []
    if regions is not None and region_grid is not None:
        missed = {f.characteristic: f.where for f in signal.local_failures if f.scope == "regions"}
        for name in missed or ["mae"]:
            drawn = local_svg.heatmap_svg(
                region_grid,
                list(regions.lambdas.get(name, [])),
                f"{describe(name).title} per cell",
                missed=missed.get(name, ()),
            )
            if drawn:
                maps.append(drawn)
    return {
        "local": local,
        "timeline": local_svg.timeline_svg(signal),
        "region_maps": maps,
        "local_failures": [_local_failure_sentence(f) for f in signal.local_failures],
    }


def _local_failure_sentence(failure: LocalFailure) -> str:
    return local_failure_text(failure, describe(failure.characteristic).title)


def _spec_view(
    index: int, spec: SpecResult, share: svg.PathShare, panels: SignalPanels
) -> dict[str, Any]:
    anchors: dict[str, str] = {}
    for j, signal in enumerate(spec.signals):
        path = signal.path or signal.name
        anchors.setdefault(path, f"spec{index}-{j}-{_slug(path)}")
    region_grid = model.region_grid(spec)
    views = {
        id(s): _signal_view(spec, index, s, anchors, share, panels, region_grid)
        for s in model.ordered_signals(spec)
    }
    tree = [(views[id(s)], depth) for s, depth in model.tree_rows(spec)]
    signals = list(views.values())
    phi = spec.phi
    min_phi = spec.min_phi
    phi_low, phi_high = model.interval_bounds(spec.phi_interval)
    runtime, model_kind = runtime_of(spec)
    return {
        "runtime_text": runtime_text(runtime, model_kind),
        "runtime_failures": runtime.failures() if runtime is not None else [],
        "phi_low": phi_low,
        "phi_high": phi_high,
        "phi_low_bar": _percent(phi_low) if phi_low is not None else None,
        "phi_high_bar": _percent(phi_high) if phi_high is not None else None,
        "min_phi_bound": model.min_phi_bound(spec),
        "spec": spec,
        "quality": model.data_quality(spec),
        "index": index,
        "anchor": f"spec{index}",
        "passed": spec.passed,
        "phi": phi,
        "min_phi": min_phi,
        "phi_bar": _percent(phi),
        "min_bar": _percent(min_phi) if model.is_finite_number(min_phi) else None,
        "phi_gap": (float(phi) - float(min_phi))
        if model.is_finite_number(phi) and model.is_finite_number(min_phi)
        else None,
        "alignment": model.alignment_of(spec),
        "glyph": plots.glyph_plot(spec, share),
        "tree": tree,
        "signals": signals,
        "failing": [v for v in signals if v["failed"]],
        "region_min_samples": region_grid.min_samples if region_grid else None,
        "region_phi": (
            local_svg.heatmap_svg(region_grid, region_grid.phi, "Φ per cell")
            if region_grid is not None
            else None
        ),
        "region_coverage": (
            local_svg.coverage_svg(region_grid) if region_grid is not None else None
        ),
        "region_unvisited": (
            [region_grid.labels[_flat(region_grid, i)] for i in region_grid.unvisited]
            if region_grid is not None
            else []
        ),
    }


def _flat(region: RegionGrid, index: Sequence[int]) -> int:
    shape = list(region.shape)
    flat = 0
    for size, i in zip(shape, index, strict=True):
        flat = flat * int(size) + int(i)
    return flat


def _environment() -> Any:
    try:
        import jinja2
    except ImportError as exc:
        raise MissingExtraError.for_extra("the HTML report", "html", "jinja2") from exc
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("pytest_hevval.report", "templates"),
        # Results may come from older or hand-written JSON: a missing optional key renders
        # as empty (and "—" through the number filters) instead of failing the whole report.
        autoescape=True,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["fmt"] = _fmt
    env.filters["fmt_g"] = _fmt_g
    return env


def render_html(
    spec_results: Sequence[SpecResult],
    *,
    title: str,
    generated_utc: str,
    formats: Collection[str] = ("html", "json"),
    verdict: RunVerdict | None = None,
    panels: SignalPanels | None = None,
) -> str:
    """The HTML report of ``spec_results`` as one self-contained page; its header says
    ``verdict`` (else the verdict of the results alone).

    Parameters
    ----------
    spec_results:
        The run's results.
    title:
        Page title and heading.
    generated_utc:
        Timestamp shown in the header; passed in so that rendering stays a pure function.
    formats:
        The reports written beside this page (the footer points to ``report.json`` only when
        it is one of them).
    panels:
        Each signal's diagnosis and history trend.
    """
    env = _environment()
    share = svg.PathShare()
    panels = panels if panels is not None else SignalPanels()
    specs = [_spec_view(i, spec, share, panels) for i, spec in enumerate(spec_results)]
    anchors = {
        (view["index"], sv["path"]): sv["anchor"] for view in specs for sv in view["signals"]
    }
    worst = [
        {
            "row": row,
            "anchor": anchors.get((row.spec_index, row.signal.path or row.signal.name)),
        }
        for row in model.worst_rows(spec_results, limit=12)
    ]
    template = env.get_template(_TEMPLATE)
    text: str = template.render(
        title=title,
        generated_utc=generated_utc,
        version=__version__,
        summary=model.summary(spec_results, verdict),
        specs=specs,
        worst=worst,
        campaigns=model.campaigns_of(spec_results, verdict),
        trace=trace_rows(spec_results),
        characteristics=model.characteristic_names(spec_results),
        labels=model.LABELS,
        short_labels=model.SHORT_LABELS,
        colours=model.CHARACTERISTIC_COLOURS,
        isfinite=model.is_finite_number,
        formats=set(formats),
    )
    return text

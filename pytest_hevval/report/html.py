"""The self-contained HTML report: one file, CSS inline, no scripts, no external URLs.

Every plot is inline SVG written directly from the result dicts: the glyph plot by
:mod:`pytest_hevval.report.plots`, the per-signal plots from the figure data by
:mod:`pytest_hevval.report.svg`, the local ones by :mod:`pytest_hevval.report.local_svg`.
Path data is drawn once per page and referred to where it repeats (:class:`svg.PathShare`).

jinja2 (autoescaping on) is imported on first use. Everything the page shows
comes from the result dicts via :mod:`pytest_hevval.report.model`, the same view-model as the
JSON and Markdown reports.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from .. import __version__
from ..core.registry import describe
from ..errors import MissingExtraError
from ..results.local import LocalFailure
from ..results.verdict import RunVerdict
from . import local_svg, model, plots, svg
from .sentences import lag_text, local_failure_text
from .terminal import runtime_of, runtime_text
from .text import campaigns_of
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
    spec_index: int,
    signal: Mapping[str, Any],
    anchors: Mapping[str, str],
    share: svg.PathShare,
) -> dict[str, Any]:
    diagnosis = signal.get("diagnosis")
    history = signal.get("history")
    failed = signal.get("passed") is False
    origins = [str(o) for o in model.items(signal.get("origins"))]
    path = str(signal.get("path") or signal.get("name") or "")
    return {
        "signal": signal,
        "path": path,
        "anchor": anchors.get(path, f"spec{spec_index}-{_slug(path)}"),
        "cells": model.cells(signal),
        "standard_metrics": model.standard_metric_rows(signal),
        "measurement": model.measurement_lines(signal),
        "lag": lag_text(signal),
        "failed": failed,
        "is_origin": failed and bool(signal.get("origin")),
        "origins": [(o, anchors.get(o)) for o in origins if o != path],
        "margin": model.margin(signal),
        "plot": svg.signal_svg(signal, f"{spec_index}-{anchors.get(path, path)}", share),
        "diagnosis": diagnosis if isinstance(diagnosis, Mapping) else None,
        "history": svg.history_svg(history) if isinstance(history, Sequence) else None,
        **_local_view(signal),
    }


def _local_view(signal: Mapping[str, Any]) -> dict[str, Any]:
    """Where and when: the window strip, phase and condition tables, the cell heat maps."""
    local = signal.get("local")
    if not isinstance(local, Mapping):
        return {"local": None}
    regions = local.get("regions")
    region_grid = signal.get("_region_grid")
    maps: list[str] = []
    if isinstance(regions, Mapping) and isinstance(region_grid, Mapping):
        missed = {
            f["characteristic"]: f.get("where", [])
            for f in model.items(signal.get("local_failures"))
            if f.get("scope") == "regions"
        }
        for name in missed or ["mae"]:
            drawn = local_svg.heatmap_svg(
                region_grid,
                regions.get("lambdas", {}).get(name, []),
                f"{describe(name).title} per cell",
                missed=missed.get(name, ()),
            )
            if drawn:
                maps.append(drawn)
    return {
        "local": local,
        "timeline": local_svg.timeline_svg(signal),
        "region_maps": maps,
        "local_failures": [
            _local_failure_sentence(f) for f in model.items(signal.get("local_failures"))
        ],
    }


def _local_failure_sentence(failure: Mapping[str, Any]) -> str:
    parsed = LocalFailure.from_dict(failure)
    return local_failure_text(parsed, describe(parsed.characteristic).title)


def _spec_view(index: int, spec: Mapping[str, Any], share: svg.PathShare) -> dict[str, Any]:
    anchors: dict[str, str] = {}
    for j, signal in enumerate(model.items(spec.get("signals"))):
        path = str(signal.get("path") or signal.get("name") or "")
        anchors.setdefault(path, f"spec{index}-{j}-{_slug(path)}")
    local = spec.get("local") if isinstance(spec.get("local"), Mapping) else None
    region_grid = local.get("regions") if local else None
    views = {
        id(s): _signal_view(
            index, {**s, "_region_grid": region_grid} if region_grid else s, anchors, share
        )
        for s in model.ordered_signals(spec)
    }
    tree = [(views[id(s)], depth) for s, depth in model.tree_rows(spec)]
    signals = list(views.values())
    phi = spec.get("phi")
    min_phi = spec.get("min_phi")
    phi_low, phi_high = model.interval_bounds(spec.get("phi_interval"))
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
        "index": index,
        "anchor": f"spec{index}",
        "passed": spec.get("passed") is not False,
        "phi": phi,
        "min_phi": min_phi,
        "phi_bar": _percent(phi),
        "min_bar": _percent(min_phi) if model.is_finite_number(min_phi) else None,
        "phi_gap": (float(phi) - float(min_phi))
        if model.is_finite_number(phi) and model.is_finite_number(min_phi)
        else None,
        "alignment": spec.get("alignment") if isinstance(spec.get("alignment"), Mapping) else {},
        "glyph": plots.glyph_plot(spec, share),
        "tree": tree,
        "signals": signals,
        "failing": [v for v in signals if v["failed"]],
        "weights": spec.get("weights"),
        "region_phi": (
            local_svg.heatmap_svg(region_grid, region_grid.get("phi", []), "Φ per cell")
            if isinstance(region_grid, Mapping)
            else None
        ),
        "region_coverage": (
            local_svg.coverage_svg(region_grid) if isinstance(region_grid, Mapping) else None
        ),
        "region_unvisited": (
            [region_grid["labels"][_flat(region_grid, i)] for i in region_grid.get("unvisited", [])]
            if isinstance(region_grid, Mapping)
            else []
        ),
    }


def _flat(region: Mapping[str, Any], index: Sequence[int]) -> int:
    shape = list(region.get("shape", []))
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
    spec_results: Sequence[Mapping[str, Any]],
    *,
    title: str,
    generated_utc: str,
    formats: Collection[str] = ("html", "json"),
    verdict: RunVerdict | None = None,
) -> str:
    """The HTML report of ``spec_results`` as one self-contained page; its header says
    ``verdict`` (else the verdict of the results alone).

    Parameters
    ----------
    spec_results:
        Per-spec result dicts (the JSON report's ``specs``).
    title:
        Page title and heading.
    generated_utc:
        Timestamp shown in the header; passed in so that rendering stays a pure function.
    formats:
        The reports written beside this page (the footer points to ``report.json`` only when
        it is one of them).
    """
    env = _environment()
    share = svg.PathShare()
    specs = [_spec_view(i, spec, share) for i, spec in enumerate(spec_results)]
    anchors = {
        (view["index"], sv["path"]): sv["anchor"] for view in specs for sv in view["signals"]
    }
    worst = [
        {
            "row": row,
            "anchor": anchors.get(
                (row.spec_index, str(row.signal.get("path") or row.signal.get("name") or ""))
            ),
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
        campaigns=campaigns_of(spec_results),
        trace=trace_rows(spec_results),
        characteristics=model.characteristic_names(spec_results),
        labels=model.LABELS,
        short_labels=model.SHORT_LABELS,
        colours=model.CHARACTERISTIC_COLOURS,
        isfinite=model.is_finite_number,
        formats=set(formats),
    )
    return text

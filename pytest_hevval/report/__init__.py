"""Reports of validation results: HTML, JSON, Markdown, CI annotations, figure data.

Importing this package is cheap: jinja2 loads only when an HTML report is
rendered, and scipy only when :func:`figure_data` first runs.
"""

from __future__ import annotations

from ..core.figures import figure_data
from .html import render_html
from .text import github_annotations, render_json, render_markdown
from .writer import ReportOptionError, parse_formats, write_reports

__all__ = [
    "ReportOptionError",
    "figure_data",
    "github_annotations",
    "parse_formats",
    "render_html",
    "render_json",
    "render_markdown",
    "write_reports",
]

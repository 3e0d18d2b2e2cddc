"""The example project's HTML report, written as a user writes it: bounded, every plot once."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

pytestmark = pytest.mark.slow

EXAMPLE = Path(__file__).resolve().parent.parent / "example_project"


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict[str, Any]]:
    """report.html and report.json of the example (the page and its data)."""
    out = tmp_path_factory.mktemp("example-report")
    run = subprocess.run(
        [sys.executable, "-m", "pytest_hevval", "run", "specs", "--report", "html,json",
         "--report-dir", str(out), "--no-history", "--quiet"],
        cwd=EXAMPLE,
        capture_output=True,
        text=True,
        timeout=600,
    )  # fmt: skip
    assert run.returncode in (0, 1), run.stderr
    page = (out / "report.html").read_text("utf-8")
    return page, json.loads((out / "report.json").read_text("utf-8"))


def _signals(data: dict[str, Any]) -> list[dict[str, Any]]:
    return [signal for spec in data["specs"] for signal in spec["signals"]]


def test_the_example_page_stays_small(report: tuple[str, dict[str, Any]]) -> None:
    page, data = report
    signals = _signals(data)
    assert len(signals) > 100
    # About 30 KB per signal; it was 69 KB when every plot kept every point of its figure data
    # at a tenth of a pixel, each plot its own copy, and every glyph plot was a bitmap.
    assert len(page.encode("utf-8")) < 33_000 * len(signals)


def test_the_example_page_holds_each_path_once(report: tuple[str, dict[str, Any]]) -> None:
    page, _ = report
    long_data = re.findall(r'\sd="([^"]{200,})"', page)
    assert long_data
    assert len(long_data) == len(set(long_data))
    ids = re.findall(r'\sid="([^"]+)"', page)
    assert len(ids) == len(set(ids))
    used = re.findall(r'<use class="[^"]+" href="#([^"]+)"/>', page)
    # The example has both kinds of repeat: speed, a model input equal to its measurement, and
    # the i3 trips that are also recordings of the campaign.
    assert used
    assert set(used) <= set(ids)
    assert "data:image" not in page


def test_the_example_page_draws_every_spec_and_signal(report: tuple[str, dict[str, Any]]) -> None:
    page, data = report
    signals = _signals(data)
    assert page.count('<svg class="hv-glyph"') == len(data["specs"])
    assert page.count('<details class="signal') == len(signals)
    assert page.count('<svg class="hv-plot"') == sum(1 for s in signals if s.get("figures"))
    plots = re.findall(r'<svg class="hv-plot".*?</svg>', page, re.S)
    for plot in plots:
        for css in ("hv-ref", "hv-sim", "hv-res", "hv-match"):
            assert len(re.findall(rf'<(?:path|g|use) class="{css}"', plot)) == 1, css

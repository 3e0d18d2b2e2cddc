"""The HTML report in a real browser: it loads cleanly and its plots are drawn.

Needs a Chromium binary. Without one the tests skip locally, but fail in CI (the ``CI``
environment variable set), where a missing browser must not pass silently.
"""

from __future__ import annotations

import copy
import html
import json
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pytest_hevval.report import model, render_html
from pytest_hevval.results.spec_result import SpecResult
from tests.conftest import IN_CI
from tests.demo_results import demo_results

pytestmark = pytest.mark.browser

_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")
_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--enable-logging=stderr",
    "--v=0",
)


def _chromium() -> str:
    """The browser binary; skips locally without one, fails (not errors) when CI is set."""
    for name in _NAMES:
        found = shutil.which(name)
        if found:
            return found
    reason = f"no Chromium binary on PATH (looked for {', '.join(_NAMES)})"
    if IN_CI:
        pytest.fail(f"{reason}; CI is set, so the browser check must run: install chromium")
    pytest.skip(f"{reason}; install chromium to run the browser checks")


# Appended to a copy of the report only: writes the page position of every plot into the DOM,
# which --dump-dom then prints, so the screenshot can be checked plot by plot.
_PROBE = """<script>
addEventListener("load", () => {
  const plots = document.querySelectorAll("svg.hv-glyph, svg.hv-plot:not(.hv-small)");
  const boxes = [...plots].map((e) => {
    const r = e.getBoundingClientRect();
    return {kind: e.classList.contains("hv-glyph") ? "glyph" : "plot", x: r.left + scrollX,
            y: r.top + scrollY, w: r.width, h: r.height};
  });
  const pre = document.createElement("pre");
  pre.id = "hv-boxes";
  pre.textContent = JSON.stringify(boxes);
  document.body.appendChild(pre);
});
</script>"""
_WINDOW = (1400, 3000)


def _run(chromium: str, page: Path, profile: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [chromium, *_FLAGS, f"--user-data-dir={profile}", *args, page.as_uri()],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )


def _screenshot(chromium: str, page: Path, png: Path, profile: Path) -> str:
    """Load ``page``, save a screenshot, return Chromium's log (console messages included)."""
    size = f"--window-size={_WINDOW[0]},{_WINDOW[1]}"
    done = _run(chromium, page, profile, f"--screenshot={png}", size)
    assert png.exists(), f"Chromium wrote no screenshot (exit {done.returncode}):\n{done.stderr}"
    return done.stderr


def _plot_boxes(chromium: str, page: Path, profile: Path) -> list[dict[str, Any]]:
    probe = page.with_name("probe.html")
    probe.write_text(page.read_text("utf-8").replace("</body>", _PROBE + "</body>"), "utf-8")
    size = f"--window-size={_WINDOW[0]},{_WINDOW[1]}"
    done = _run(chromium, probe, profile, "--dump-dom", size)
    found = re.search(r'<pre id="hv-boxes">(.*?)</pre>', done.stdout, re.S)
    assert found, f"no plot positions in the dumped DOM:\n{done.stderr[-2000:]}"
    boxes: list[dict[str, Any]] = json.loads(html.unescape(found.group(1)))
    return boxes


def _console_errors(log: str) -> list[str]:
    return [
        line
        for line in log.splitlines()
        if ":CONSOLE" in line or "Uncaught" in line or "Failed to load resource" in line
    ]


def _pixels(png: Path) -> np.ndarray:
    image = pytest.importorskip("matplotlib.image")
    rgb = np.asarray(image.imread(str(png)))[..., :3]
    return np.rint(rgb * 255).astype(np.int16) if rgb.dtype != np.uint8 else rgb.astype(np.int16)


def _crop(pixels: np.ndarray, box: dict[str, Any]) -> np.ndarray:
    x0, y0 = round(box["x"]), round(box["y"])
    return pixels[y0 : y0 + round(box["h"]), x0 : x0 + round(box["w"])]


def _near(pixels: np.ndarray, hex_colour: str, tol: int, alpha: float = 1.0) -> int:
    """Pixels within ``tol`` of ``hex_colour`` drawn with ``alpha`` over white."""
    rgb = np.array([int(hex_colour[i : i + 2], 16) for i in (1, 3, 5)], dtype=np.float64)
    target = np.rint(alpha * rgb + (1.0 - alpha) * 255.0).astype(np.int16)
    return int((np.abs(pixels - target).max(axis=-1) <= tol).sum())


def test_console_capture_sees_a_script_error(tmp_path: Path) -> None:
    """The check below is only worth something if a broken page is caught."""
    chromium = _chromium()
    page = tmp_path / "broken.html"
    page.write_text("<html><body><p>x</p><script>undefined_fn();</script></body></html>")
    log = _screenshot(chromium, page, tmp_path / "broken.png", tmp_path / "profile")
    assert _console_errors(log), log


def test_report_loads_without_console_errors_and_draws_its_plots(tmp_path: Path) -> None:
    chromium = _chromium()
    results = [SpecResult.from_dict(r) for r in demo_results(specs=1, duration_s=300.0, seed=3)]
    page = tmp_path / "report.html"
    page.write_text(render_html(results, title="browser check", generated_utc="now"), "utf-8")
    png = tmp_path / "report.png"
    log = _screenshot(chromium, page, png, tmp_path / "profile")
    assert not _console_errors(log), "\n".join(_console_errors(log))
    pixels = _pixels(png)
    assert pixels.shape[:2] == (_WINDOW[1], _WINDOW[0])

    boxes = _plot_boxes(chromium, page, tmp_path / "profile")
    glyphs = [b for b in boxes if b["kind"] == "glyph"]
    overlays = [b for b in boxes if b["kind"] == "plot"]
    assert len(glyphs) == 1
    assert len(overlays) == 7
    assert glyphs[0]["w"] > 1000
    assert glyphs[0]["h"] > 300, "the glyph plot has no height"
    first = overlays[0]
    assert first["y"] + first["h"] < _WINDOW[1], "the first signal plot is below the screenshot"

    # Glyph plot: glyphs filled with the characteristic colours (alpha 0.85 over white).
    glyph = _crop(pixels, glyphs[0])
    for name, colour in (("λ2", "#E69F00"), ("λ3", "#009E73"), ("λ5", "#CC79A7")):
        assert _near(glyph, colour, 25, alpha=0.85) > 300, f"no {name} glyphs drawn"

    _assert_signal_plot_drawn(_crop(pixels, first))


def _assert_signal_plot_drawn(plot: np.ndarray) -> None:
    """Reference and simulated envelopes, the residual beneath, the derivative-match strip."""
    assert np.unique(plot.reshape(-1, 3) // 8, axis=0).shape[0] > 100, "signal plot looks blank"
    assert _near(plot, "#1f2328", 10, alpha=0.28) > 1000, "reference envelope not drawn"
    assert _near(plot, "#0969da", 40) > 600, "simulated trace not drawn"
    assert _near(plot, "#8250df", 12, alpha=0.35) > 300, "residual not drawn"
    red, green, blue = plot[..., 0], plot[..., 1], plot[..., 2]
    assert ((green > red + 40) & (green > blue + 30)).sum() > 2000, "derivative match not drawn"


def test_a_plot_drawn_by_reference_to_a_closed_section_is_drawn(tmp_path: Path) -> None:
    """A page draws path data it already holds by reference (``<use>``); the copy it refers to
    may sit in a signal section that is closed, and must be drawn all the same."""
    chromium = _chromium()
    (spec,) = demo_results(specs=1, duration_s=300.0, rate_hz=10.0, seed=3)
    # After the first three, and passing: closed.
    closed = model.ordered_signals(SpecResult.from_dict(spec))[-1]
    assert closed.passed
    twin = {**copy.deepcopy(spec), "name": "the same recording again"}
    twin["signals"] = [copy.deepcopy(s) for s in spec["signals"] if s["path"] == closed.path]
    typed = [SpecResult.from_dict(spec), SpecResult.from_dict(twin)]
    text = render_html(typed, title="shared plots", generated_utc="now")
    plots = re.findall(r'<svg class="hv-plot".*?</svg>', text, re.S)
    shared = re.findall(r'<use class="hv-(?:ref|sim|res|match)" href="#([^"]+)"', plots[-1])
    assert len(shared) == 4
    for ident in shared:
        opening = text.rfind("<details", 0, text.index(f'id="{ident}"'))
        assert " open>" not in text[opening : text.index(">", opening) + 1]
    page = tmp_path / "report.html"
    page.write_text(text, "utf-8")

    box = _plot_boxes(chromium, page, tmp_path / "profile")[-1]
    assert box["kind"] == "plot"
    assert box["h"] > 300
    png = tmp_path / "report.png"
    height = int(box["y"] + box["h"]) + 40
    done = _run(
        chromium,
        page,
        tmp_path / "profile",
        f"--screenshot={png}",
        f"--window-size={_WINDOW[0]},{height}",
    )
    assert png.exists(), done.stderr
    _assert_signal_plot_drawn(_crop(_pixels(png), box))

"""One escaping rule per output channel, for text that comes from specs, data files' headers,
file names, model versions or history records.

- **Terminal and CI log** (:func:`terminal`, :class:`TerminalStream`): control characters,
  escape sequences and the bidirectional overrides become visible escapes (``\\u001b``), so that
  no text can clear a screen, move the cursor or hide what follows; and a line that would start
  with ``::`` (after blanks, which GitHub's runner skips) gets a backslash first, so that no
  text becomes a workflow command (``::error``, ``::add-mask``, ``::stop-commands``). The
  project's own annotations are the only workflow commands it prints, and they bypass this.
- **Markdown** (:func:`markdown`, :func:`markdown_code`): the same control characters, then
  no raw HTML, no table breaks, no code span broken out of.
- **Plot labels** (:func:`plot_text`): matplotlib reads ``$…$`` as maths markup, which a
  name may hold without meaning it.
- **HTML**: jinja2's autoescape and ``html.escape`` (``report/html.py``, ``report/svg.py``).

Every front end (``hevval`` and ``pytest --hevval``) and every command writes through these.
"""

from __future__ import annotations

import re
from typing import IO, Any

__all__ = ["TerminalStream", "markdown", "markdown_code", "plot_text", "terminal"]

#: C0 controls but tab and line feed, DEL, C1 controls (CSI among them), the line and paragraph
#: separators and the bidirectional embeddings, overrides and isolates.
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")
#: A GitHub workflow command: ``::`` at the start of a line, after any blanks.
_WORKFLOW_COMMAND = re.compile(r"^(\s*)(?=::)", re.MULTILINE)


def _visible(match: re.Match[str]) -> str:
    # The form JSON reads back as the same character, so JSON printed stays JSON.
    return f"\\u{ord(match.group()):04x}"


def _controls(text: str) -> str:
    return _CONTROL.sub(_visible, text)


def terminal(text: object) -> str:
    """``text`` safe to print to a terminal or a CI log (line feeds kept)."""
    return _WORKFLOW_COMMAND.sub(r"\1\\", _controls(str(text)))


def markdown(text: object) -> str:
    """``text`` safe inside GitHub Markdown and a table cell: no raw HTML, no table breaks."""
    return (
        _controls(str(text))
        .replace("\\", "\\\\")
        .replace("|", "\\|")
        .replace("`", "\\`")
        .replace("<", "&lt;")
        .replace(">", "&gt;")
        .replace("\n", " ")
    )


def markdown_code(text: object) -> str:
    """``text`` as an inline code span that nothing in it can end early."""
    # Inside a code span a backslash escapes nothing: the backtick becomes a quote.
    body = markdown(str(text).replace("`", "'"))
    return f"`{body}`"


def plot_text(text: object) -> str:
    """``text`` as a matplotlib label shows it: dollar signs literal, controls visible."""
    return _controls(str(text)).replace("$", r"\$")


class TerminalStream:
    """A text stream that writes everything through :func:`terminal`, and what its encoding
    cannot hold (``Φ`` on an ASCII console) as backslash escapes rather than failing.

    ``raw`` is the stream underneath: for the project's own workflow commands only."""

    def __init__(self, raw: IO[str]) -> None:
        self.raw = raw
        self._line_start = True

    def write(self, text: str) -> int:
        safe = _controls(text)
        if self._line_start:
            safe = _WORKFLOW_COMMAND.sub(r"\1\\", safe)
        else:
            head, newline, rest = safe.partition("\n")
            safe = head + newline + _WORKFLOW_COMMAND.sub(r"\1\\", rest) if newline else safe
        if safe:
            self._line_start = safe.endswith("\n")
        encoding = getattr(self.raw, "encoding", None) or "utf-8"
        try:
            safe.encode(encoding)
        except (UnicodeEncodeError, LookupError):
            safe = safe.encode(encoding, "backslashreplace").decode(encoding, "replace")
        self.raw.write(safe)
        return len(text)

    def writeraw(self, text: str) -> None:
        """Write the project's own text (its workflow commands) as it is."""
        self.raw.write(text)
        self._line_start = text.endswith("\n") if text else self._line_start

    def flush(self) -> None:
        self.raw.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.raw, name)

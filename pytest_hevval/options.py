"""Every ``--hevval-*`` option and its same-named ``hevval_*`` ini key, in one table (an
option given on the command line only, such as ``--hevval-accept``, has no ini key).

Precedence: command line > ini file (pytest.ini / pyproject / tox.ini / setup.cfg) > built-in
default. Values are validated when read, with messages that say what to do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import pytest

from .data.digest import DEFAULT_HASH, HASH_CHOICES
from .defaults import HISTORY_DIR, REPORT_DIR, SPEC_GLOBS

__all__ = ["OPTIONS", "Option", "add_options", "get_option", "option_named", "snapshot"]

Kind = Literal["bool", "string", "linelist", "choice"]


@dataclass(frozen=True)
class Option:
    name: str  # without the leading "hevval" prefix, e.g. "report-dir"
    kind: Kind
    help: str
    default: Any = None
    choices: tuple[str, ...] = ()
    #: For string options that may be given bare (``--hevval-compare``): the bare value.
    const: str | None = None
    #: Given on the command line only, never by an ini key: an act of one run, which a
    #: setting in a committed file must not make the rule for every run.
    command_line_only: bool = False

    @property
    def flag(self) -> str:
        return "--hevval" if not self.name else f"--hevval-{self.name}"

    @property
    def ini(self) -> str:
        return "hevval" if not self.name else "hevval_" + self.name.replace("-", "_")

    @property
    def dest(self) -> str:
        return self.ini


OPTIONS: tuple[Option, ...] = (
    Option("", "bool", "run validation specs (*.hevval.yaml) as tests", False),
    Option(
        "files",
        "linelist",
        "glob patterns of spec files (ini only)",
        list(SPEC_GLOBS),
    ),
    Option("details", "bool", "show every node of every tree in the summary", False),
    Option(
        "diagnose",
        "choice",
        "diagnose residuals of failing signals (off, failed, all)",
        "failed",
        ("off", "failed", "all"),
    ),
    Option("report", "string", "write reports: comma-separated html,json,md,evidence", ""),
    Option("report-dir", "string", "folder for reports", REPORT_DIR),
    Option(
        "history",
        "bool",
        "record this run in the history folder (runs in CI are recorded without it)",
        False,
    ),
    Option("no-history", "bool", "neither record this run nor read the history", False),
    Option("history-dir", "string", "folder of run records", HISTORY_DIR),
    Option("model-version", "string", "model version recorded in the history", None),
    Option(
        "compare",
        "string",
        "compare with a recorded run: latest (the newest record, the default), accepted (the "
        "newest record accepted as a baseline) or a model version",
        None,
        const="latest",
    ),
    Option(
        "compare-fail",
        "string",
        "fail items that got worse than EXPR against the baseline, e.g. phi:0.01,lambda:0.02",
        None,
    ),
    Option("create-baseline", "bool", "record a baseline when none exists (also in CI)", False),
    Option(
        "accept",
        "bool",
        "record this run as an accepted baseline even when it regressed (regressions are "
        "then reported, not failed); also records a first baseline (command line only)",
        False,
        command_line_only=True,
    ),
    Option(
        "ratchet",
        "string",
        "write tightened thresholds (achieved minus MARGIN) to a sidecar file",
        None,
        const="0.01",
    ),
    Option("dask", "string", "evaluate specs on this dask.distributed scheduler address", None),
    Option(
        "workers",
        "string",
        "threads per spec for scoring and diagnosing signals (default 2; on an xdist worker, "
        "its share of the cores)",
        None,
    ),
    Option(
        "hash",
        "choice",
        "identify data files in results and history by a fast hash (xxh3_128, else sampled) "
        "or by sha256",
        DEFAULT_HASH,
        HASH_CHOICES,
    ),
    Option(
        "no-intervals",
        "bool",
        "skip the bootstrap intervals of λ and Φ (a min_phi bound is then judged on Φ)",
        False,
    ),
)

_BY_NAME = {o.name: o for o in OPTIONS}


def option_named(name: str) -> Option:
    """The option pytest spells ``--hevval-NAME`` (the command line reuses its help/default)."""
    return _BY_NAME[name]


def add_options(parser: pytest.Parser) -> None:
    group = parser.getgroup("hevval", "multi-fidelity model validation (pytest-hevval)")
    for option in OPTIONS:
        if option.kind == "linelist":
            parser.addini(option.ini, option.help, type="linelist", default=option.default)
            continue
        if option.kind == "bool":
            group.addoption(
                option.flag, action="store_true", default=None, dest=option.dest, help=option.help
            )
            if not option.command_line_only:
                parser.addini(option.ini, option.help, type="bool", default=option.default)
            continue
        kwargs: dict[str, Any] = {"dest": option.dest, "default": None, "help": option.help}
        if option.choices:
            kwargs["choices"] = option.choices
        if option.const is not None:
            kwargs["nargs"] = "?"
            kwargs["const"] = option.const
        group.addoption(option.flag, **kwargs)
        parser.addini(
            option.ini,
            option.help,
            type="string",
            default="" if option.default is None else str(option.default),
        )


def get_option(config: pytest.Config, name: str) -> Any:
    """The option's value: command line, else ini, else the built-in default."""
    option = _BY_NAME[name]
    if option.kind == "linelist":
        return config.getini(option.ini)
    cli = config.getoption(option.dest, default=None)
    if cli is not None:
        return cli
    if option.command_line_only:
        return option.default
    value = config.getini(option.ini)
    if option.kind == "bool":
        return bool(value)
    if value in ("", None):
        return option.default
    if option.choices and value not in option.choices:
        raise pytest.UsageError(
            f"ini {option.ini} = {value!r}: must be one of {', '.join(option.choices)}"
        )
    return value


def snapshot(config: pytest.Config) -> dict[str, Any]:
    """Every option's value, read once for the session (:func:`get_option` of each)."""
    return {option.name: get_option(config, option.name) for option in OPTIONS}

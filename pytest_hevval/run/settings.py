"""What one run was asked to do, read once from the front end's options.

``pytest --hevval`` reads its ``--hevval-*`` flags and ini keys, ``hevval run`` its command
line; both give :meth:`RunSettings.read` a getter over the names of
:data:`pytest_hevval.options.OPTIONS`, and from then on the run reads these settings, never
the options again. The checks of option values that both front ends take (the number of
workers) and what the environment says about the run (CI) are made here, once.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..data.digest import DEFAULT_HASH
from ..defaults import SPEC_GLOBS
from ..errors import HevvalError
from ..flags import FrontEnd
from ..publish import PublishOptions

__all__ = ["RunSettings", "worker_count"]


def worker_count(text: str) -> int:
    """The number of scoring threads a ``workers`` option gives; ``ValueError`` saying what is
    wrong with it (each front end names its own flag before the text)."""
    try:
        count = int(text)
    except ValueError:
        raise ValueError(f"must be a whole number (got {text!r})") from None
    if count < 1:
        raise ValueError(f"must be ≥ 1 (got {count})")
    return count


@dataclass(frozen=True)
class RunSettings:
    """Every option of one run, as its front end gave it, checked."""

    #: The front end in use: every message about an option names its flag.
    front_end: FrontEnd
    #: The project root: model callables import from here; result paths are relative to it.
    rootdir: Path
    #: What the run leaves behind (reports, comparison, ratchet, history record).
    publish: PublishOptions
    #: Show every node of every tree in the summary.
    details: bool = False
    #: Glob patterns of spec files (pytest's collection).
    files: tuple[str, ...] = SPEC_GLOBS
    #: Threads that score one spec's signals; None is the engine's default.
    workers: int | None = None
    #: A dask.distributed scheduler address: the specs are scored there.
    dask: str | None = None
    data_hash: str = DEFAULT_HASH
    intervals: bool = True
    #: Which signals' residuals to diagnose: ``off``, ``failed`` or ``all``.
    diagnose: str = "failed"
    #: The front end reports each failing item with its diagnosis (pytest); otherwise only a
    #: report file shows diagnoses, and a run without one makes none.
    item_reports: bool = False

    @classmethod
    def read(
        cls,
        option: Callable[[str], Any],
        rootdir: Path,
        front_end: FrontEnd,
        *,
        processes: int | None = None,
        item_reports: bool = False,
        environ: Mapping[str, str] = os.environ,
    ) -> RunSettings:
        """The settings from ``option`` (a getter over the option table's names; None for an
        option this front end does not have). ``processes``: how many processes score specs
        side by side (an xdist worker's count), which share the cores.

        Raises :class:`~pytest_hevval.errors.HevvalError` for a value that cannot work, naming
        the front end's flag.
        """
        dask = option("dask")
        return cls(
            front_end=front_end,
            rootdir=rootdir,
            publish=PublishOptions.from_options(option, rootdir, front_end, environ),
            details=bool(option("details")),
            files=tuple(option("files") or SPEC_GLOBS),
            workers=_workers(option("workers"), front_end, processes),
            dask=str(dask) if dask else None,
            data_hash=str(option("hash") or DEFAULT_HASH),
            intervals=not option("no-intervals"),
            diagnose=str(option("diagnose") or "off"),
            item_reports=item_reports,
        )


def _workers(value: Any, front_end: FrontEnd, processes: int | None) -> int | None:
    """``workers`` as given (a command line parses it with :func:`worker_count` already), else,
    in one of several processes, its share of the cores: the processes already fill them, and
    more threads only contend."""
    if value in (None, ""):
        if processes is None:
            return None
        return max(1, (os.cpu_count() or 1) // max(processes, 1))
    if isinstance(value, int):
        return value
    try:
        return worker_count(str(value))
    except ValueError as exc:
        raise HevvalError(f"{front_end.flag('workers')} {exc}") from None

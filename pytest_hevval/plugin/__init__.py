"""pytest hooks. Each is a few lines that delegate; nothing here computes.

Registered through the ``pytest11`` entry point; inert unless ``--hevval`` (or ini
``hevval = true``) is given. Until then it imports nothing but pytest and the option table, so
installing the plugin costs other test runs in the environment nothing (see
``benchmarks/bench_startup.py``).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Generator
from pathlib import Path
from typing import Any

import pytest

from ..errors import HevvalError
from ..options import add_options, get_option
from .stash import session_key, state_of


def pytest_addoption(parser: pytest.Parser) -> None:
    add_options(parser)


def pytest_configure(config: pytest.Config) -> None:
    if not get_option(config, ""):
        return
    from .session import HevvalSession

    state = HevvalSession(config)
    config.stash[session_key] = state
    state.validate_options()
    from ..core.registry import load_entry_points

    try:
        load_entry_points()
    except HevvalError as exc:
        raise pytest.UsageError(str(exc)) from None
    # The session object receives worker reports itself (pytest_runtest_logreport).
    config.pluginmanager.register(state, "hevval-session")


def pytest_collect_file(parent: pytest.Collector, file_path: Path) -> pytest.Collector | None:
    state = state_of(parent.config)
    if state is None:
        return None
    patterns = state.option("files")
    if any(fnmatch.fnmatch(file_path.name, pattern) for pattern in patterns):
        from .items import SpecFile

        return SpecFile.from_parent(parent, path=file_path)
    return None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    report = yield
    if call.when == "call":
        # Plain JSON-safe data rides on the report, so it reaches the xdist controller.
        payload = getattr(item, "hevval_payload", None)
        if payload is not None:
            report.hevval_spec = payload  # type: ignore[attr-defined]
        diagnosis = getattr(item, "hevval_diagnosis", None)
        if diagnosis is not None:
            report.hevval_diagnosis = diagnosis  # type: ignore[attr-defined]
        campaign = getattr(item, "hevval_campaign", None)
        if campaign:
            report.hevval_campaign = campaign  # type: ignore[attr-defined]
    return report


def pytest_sessionstart(session: pytest.Session) -> None:
    state = state_of(session.config)
    if state is not None:
        state.start()


# Last: a gate deselected with -k or -m is not judged, as without xdist.
@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(
    session: pytest.Session, config: pytest.Config, items: list[pytest.Item]
) -> None:
    state = state_of(config)
    if state is not None and not state.is_controller:
        from .items import defer_campaign_gates

        items[:] = defer_campaign_gates(items, state)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: Any) -> None:
    state = state_of(node.config)
    if state is not None:
        state.receive_gates(getattr(node, "workeroutput", None) or {})


# First: the campaign gates judged here must reach JUnit XML before it is written.
@pytest.hookimpl(tryfirst=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    state = state_of(session.config)
    if state is not None and state.is_controller:
        state.finish(session)


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    state = state_of(config)
    if state is not None and state.is_controller:
        state.summarise(terminalreporter)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """Keep every item of one spec, or of one recording of a campaign, on one worker, so each
    data file is read once and a campaign's recordings spread over the workers."""
    if state_of(config) is None or config.getoption("dist", "load") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    # Its scope of a node id is all but the last ``::`` part: the spec file for a spec's items,
    # ``file::recording`` for a campaign recording's.
    return LoadScopeScheduling(config, log)

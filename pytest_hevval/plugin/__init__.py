"""pytest hooks. Each is a few lines that delegate; nothing here computes.

Registered through the ``pytest11`` entry point; inert unless ``--hevval`` (or ini
``hevval = true``) is given. Until then it imports nothing but pytest and the option table, so
installing the plugin costs other test runs in the environment nothing (see
``benchmarks/bench_startup.py``).
"""

from __future__ import annotations

import fnmatch
import os
from collections.abc import Generator, Iterator
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
    from ..files import remove_temporaries_on_signals
    from .session import HevvalSession

    remove_temporaries_on_signals()
    state = HevvalSession.configure(config)
    config.stash[session_key] = state
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
    patterns = state.run.settings.files
    if any(fnmatch.fnmatch(file_path.name, pattern) for pattern in patterns):
        from .items import SpecFile

        return SpecFile.from_parent(parent, path=file_path)
    return None


@pytest.hookimpl(wrapper=True)
def pytest_collect_directory(
    path: Path, parent: pytest.Collector
) -> Generator[None, pytest.Collector | None, pytest.Collector | None]:
    """A spec that is a dangling symbolic link or a link loop is neither a file nor a folder,
    so pytest's walk passes it by without a word; collected as a spec, it is an error that
    says why it cannot be read."""
    collector = yield
    state = state_of(parent.config)
    if collector is None or state is None:
        return collector
    patterns = state.run.settings.files
    try:
        broken = sorted(
            Path(entry.path)
            for entry in os.scandir(path)
            if any(fnmatch.fnmatch(entry.name, pattern) for pattern in patterns)
            and entry.is_symlink()
            and not os.path.exists(entry.path)
        )
    except OSError:
        return collector
    if broken:
        walk = collector.collect

        def collect() -> Iterator[pytest.Item | pytest.Collector]:
            yield from walk()
            for file_path in broken:
                yield from collector.ihook.pytest_collect_file(
                    file_path=file_path, parent=collector
                )

        collector.collect = collect  # type: ignore[method-assign]
    return collector


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
    carried = getattr(item, "hevval_carried", None)
    if carried is not None and (call.when == "call" or report.failed):
        report.hevval_carried = carried  # type: ignore[attr-defined]
        item.hevval_carried = None  # type: ignore[attr-defined]
    return report


def pytest_sessionstart(session: pytest.Session) -> None:
    state = state_of(session.config)
    if state is not None:
        state.session = session
        state.start()


# Last: a gate deselected with -k or -m is not judged, as without xdist.
@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(
    session: pytest.Session, config: pytest.Config, items: list[pytest.Item]
) -> None:
    state = state_of(config)
    if state is None:
        return
    if not state.is_controller:
        from .items import carry_spec_items, defer_campaign_gates

        items[:] = defer_campaign_gates(items, state)
        if config.workerinput.get(_CARRY):  # type: ignore[attr-defined]
            carry_spec_items(items)
    elif state.run.settings.dask:
        # Scored on the cluster: this process only judges and reports, one item per spec.
        from .items import carry_spec_items

        carry_spec_items(items)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> bool | None:
    """An item that another item of its spec judges and reports is not run on its own
    (``items.carry_spec_items``; read as an attribute, so other test runs import nothing)."""
    return True if getattr(item, "carried_by", None) is not None else None


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node: Any, error: Any) -> None:
    state = state_of(node.config)
    if state is not None:
        state.receive_gates(getattr(node, "workeroutput", None) or {})


# First: the campaign gates judged here must reach JUnit XML before it is written.
@pytest.hookimpl(tryfirst=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    state = state_of(session.config)
    if state is not None:
        state.end(session)


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    state = state_of(config)
    if state is not None and state.is_controller:
        state.summarise(terminalreporter)


#: Set in a worker's input when its spec items reach it whole and in collection order (the
#: plugin's scheduler), so one item per spec can judge and report the others.
_CARRY = "hevval_carry_spec_items"


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node: Any) -> None:
    # A worker's own --dist is always "no": the controller says which scheduler it runs.
    config = node.config
    if state_of(config) is not None:
        node.workerinput[_CARRY] = config.getoption("dist", "load") == "load"


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """Keep every item of one spec, or of one recording of a campaign, on one worker, so each
    data file is read once and a campaign's recordings spread over the workers."""
    if state_of(config) is None or config.getoption("dist", "load") != "load":
        return None
    from .scheduling import SpecScheduling

    return SpecScheduling(config, log)

"""Shared test set-up.

Inline pytester runs (``pytester.runpytest``) restore ``sys.modules`` afterwards, removing
whatever the run imported. The plugin imports the engine only once ``--hevval`` is given, and
the readers import pandas and pyarrow only when a file is read, so the first inline run would
import them and the restore would remove them again. A second import of numpy's C extensions,
or of pyarrow's extension types, in one process fails. Importing them here keeps them loaded
for the whole test session, whatever order the tests run in.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import os

import pytest
from hypothesis import settings

from pytest_hevval.data import kernel_cache
from pytest_hevval.history.policy import CI_VARIABLES, is_ci
from pytest_hevval.plugin import session
from pytest_hevval.scoring import engine

# In CI every run draws the same examples, so a pass or a failure can be reproduced; locally
# hypothesis keeps drawing new ones (and replays the failures it saved in .hypothesis/).
settings.register_profile("ci", derandomize=True)
#: Whether this test run is a CI job; the tests themselves run as on a workstation (below).
IN_CI = is_ci(os.environ)
if IN_CI:
    settings.load_profile("ci")


@pytest.fixture(autouse=True)
def _outside_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test sees no CI variables: what a run records, and how a missing baseline ends,
    depend on them; a test that needs CI sets them itself."""
    for name in CI_VARIABLES:
        monkeypatch.delenv(name, raising=False)


_KEPT_LOADED = [engine, session, importlib.import_module("pandas")]
with contextlib.suppress(ImportError):  # the parquet extra
    _KEPT_LOADED.append(importlib.import_module("pyarrow"))
    # pandas registers its Arrow extension types (pandas.period, pandas.interval) with pyarrow
    # on this module's first import; a second import after an inline run fails.
    _KEPT_LOADED.append(importlib.import_module("pandas.core.arrays.arrow.extension_types"))
# The importlib_metadata backport (dask imports it on Python < 3.12, canmatrix on any) deletes
# the standard library's PathFinder.find_distributions on import and puts its own finder on
# sys.meta_path instead. Imported first inside a test that uses pytester, its finder is taken
# off sys.meta_path again when pytester restores it, and the process is left with no finder of
# installed distributions at all: every later inline run loads no pytest11 plugin and rejects
# --hevval. Imported here, its finder stays for the whole session.
with contextlib.suppress(ImportError):
    _KEPT_LOADED.append(importlib.import_module("importlib_metadata"))
# A run with numba's cache cold compiles the kernel in a background process and says so in its
# summary; tests of that set this back (tests/test_kernel.py), the others must not depend on
# whether an earlier test warmed the cache.
os.environ[kernel_cache.BACKGROUND_COMPILE_ENV] = "0"
# The compiled kernel (the fast extra) loads numba on first use; an inline run would unload it
# and the next would pay its import again.
with contextlib.suppress(Exception):
    _KEPT_LOADED.append(importlib.import_module("pytest_hevval.core._fused"))
    # numba imports more of itself on its first compile (its typing registries); an inline
    # run would unload those and the next compile would register them twice.
    from numba.core.registry import cpu_target

    cpu_target.target_context.refresh()


def _kernel_unavailable() -> str | None:
    """Why the compiled kernel cannot run here, or None when it can."""
    from pytest_hevval.core import kernel

    if importlib.util.find_spec("numba") is None:
        return 'numba is not installed (the "fast" extra)'
    if kernel._load() is None:
        return f"numba cannot be loaded: {kernel_cache.describe()}"
    return None


#: Skips a test where the compiled kernel cannot run.
needs_kernel = pytest.mark.skipif(
    _kernel_unavailable() is not None, reason=str(_kernel_unavailable())
)


@pytest.fixture(params=["numpy", "numba"])
def kernel_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Runs a test once on the numpy reference path and once on the compiled kernel."""
    from pytest_hevval.core.kernel import KERNEL_ENV

    path: str = request.param
    if path == "numba":
        reason = _kernel_unavailable()
        if reason is not None:
            pytest.skip(reason)
    monkeypatch.setenv(KERNEL_ENV, path)
    return path


@pytest.fixture
def one_kernel_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Pins every process of a test to the numpy path.

    On the auto path a short record takes the compiled kernel once numba's on-disk cache is
    warm, and the two paths agree only to rounding. A test comparing results from two
    processes bit for bit would flake whenever another test warmed the cache in between.
    """
    from pytest_hevval.core.kernel import KERNEL_ENV

    monkeypatch.setenv(KERNEL_ENV, "numpy")

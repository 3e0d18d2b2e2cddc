"""Installing the plugin must not slow down, or load the numeric stack into, other test runs."""

from __future__ import annotations

import subprocess
import sys

import pytest

HEAVY = ("numpy", "pandas", "scipy", "matplotlib", "pyarrow", "yaml")


def test_importing_the_plugin_module_loads_no_numeric_stack() -> None:
    code = (
        "import sys, pytest_hevval.plugin, pytest_hevval\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""


def test_a_run_without_hevval_loads_no_numeric_stack(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(
        f"""
        import sys

        def test_nothing_heavy_was_imported():
            assert [m for m in {HEAVY!r} if m in sys.modules] == []
        """
    )
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=1)


def test_the_public_api_resolves_on_first_use() -> None:
    code = (
        "import sys, pytest_hevval\n"
        "assert 'numpy' not in sys.modules\n"
        "from pytest_hevval import global_metric, signal_characteristics\n"
        "assert 'numpy' in sys.modules\n"
        "print(global_metric.__module__, signal_characteristics.__module__)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == [
        "pytest_hevval.core.tree",
        "pytest_hevval.core.characteristics",
    ]


def test_an_unknown_public_name_is_an_attribute_error() -> None:
    import pytest_hevval

    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        _ = pytest_hevval.no_such_name  # type: ignore[attr-defined]


def test_scoring_loads_the_standard_metrics_only_for_a_spec_that_names_them() -> None:
    # Their package imports scipy.signal (ISO/TS 18571's filter): a tenth of a second and tens
    # of megabytes that a run without `metrics:` need not pay.
    code = (
        "import sys\n"
        "import pytest_hevval.scoring.engine, pytest_hevval.scoring.run\n"
        "print(','.join(m for m in ('pytest_hevval.core.standard', 'scipy.signal') "
        "if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == ""


def test_the_package_imports_its_own_modules_one_thread_at_a_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Under pytest the plugin's modules are parsed by the assertion rewriter, which on Python
    3.11 fails when two threads parse at once (specs evaluated side by side on Dask threads
    import their readers on first use): the package's lazy imports take turns."""
    import importlib
    import threading
    import time

    from pytest_hevval import lazy

    inside = [0]
    most = [0]
    guard = threading.Lock()

    def slow_import(name: str, package: str | None = None) -> object:
        with guard:
            inside[0] += 1
            most[0] = max(most[0], inside[0])
        time.sleep(0.02)
        with guard:
            inside[0] -= 1
        return object()

    monkeypatch.setattr(importlib, "import_module", slow_import)
    threads = [
        threading.Thread(target=lazy.import_own, args=(f".readers.m{k}", "pytest_hevval.data"))
        for k in range(4)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert most[0] == 1

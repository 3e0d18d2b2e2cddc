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

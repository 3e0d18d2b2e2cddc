"""Run after a test file by ``.ci/each-file-alone``: an inline pytester run still loads the plugin.

A test file can leave the process unable to run pytest inline (an import made first inside a
pytester test, and undone by pytester's restore, once removed every finder of installed
distributions, so inline runs loaded no pytest11 plugin and rejected ``--hevval``). Such a
file passes alone and breaks whichever file runs after it; this test, run after each file,
names the file that did it.
"""

from __future__ import annotations

import pytest

pytest_plugins = ["pytester"]


def test_an_inline_run_still_takes_the_plugin_options(pytester: pytest.Pytester) -> None:
    result = pytester.runpytest("--hevval", "--collect-only", "-q")
    assert result.ret == pytest.ExitCode.NO_TESTS_COLLECTED, result.stderr.str()

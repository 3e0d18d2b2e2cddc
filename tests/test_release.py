"""The release a model team installs: version, changelog, and the workflow they copy."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import yaml
from packaging.requirements import Requirement

import pytest_hevval

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW = ROOT / "example_project" / ".github" / "workflows" / "validate.yml"


def _pyproject_version() -> str:
    found = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.M)
    assert found is not None
    return found.group(1)


def _extras() -> set[str]:
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.optional-dependencies]", 1)[1].split("\n[", 1)[0]
    return set(re.findall(r"^([a-z0-9_-]+) = \[", block, re.M))


def test_the_version_has_one_source() -> None:
    assert pytest_hevval.__version__ == _pyproject_version()
    done = subprocess.run(
        [sys.executable, "-m", "pytest_hevval", "--version"],
        capture_output=True,
        text=True,
        check=True,
    )
    version, path = done.stdout.strip().splitlines()
    assert version == f"pytest-hevval {_pyproject_version()}"
    assert path.startswith("kernel: ")


def test_the_changelog_has_this_version() -> None:
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert f"## [{_pyproject_version()}]" in changelog


def test_the_workflow_installs_a_pinned_installable_source() -> None:
    workflow = yaml.safe_load(WORKFLOW.read_text())
    requirement_text = workflow["env"]["HEVVAL_REQUIREMENT"]
    steps = workflow["jobs"]["validate"]["steps"]
    install = next(step for step in steps if step.get("name") == "Install")
    assert install["run"] == 'python -m pip install "$HEVVAL_REQUIREMENT"'
    requirement = Requirement(requirement_text)  # raises on anything pip would refuse
    assert requirement.name == "pytest-hevval"
    assert requirement.extras <= _extras()
    assert requirement.url is not None
    assert requirement.url.startswith("git+https://")
    # Pinned to the release tag of this version, so a run never changes with the tool.
    assert requirement.url.endswith(f"@v{_pyproject_version()}")
    # The index form given in the comment names the same version and extras.
    index_form = re.search(r'HEVVAL_REQUIREMENT: "(pytest-hevval\[[^"]+)"', WORKFLOW.read_text())
    assert index_form is not None
    pinned = Requirement(index_form.group(1))
    assert str(pinned.specifier) == f"=={_pyproject_version()}"
    assert pinned.extras == requirement.extras


def test_the_workflow_still_reports() -> None:
    workflow = yaml.safe_load(WORKFLOW.read_text())
    steps = workflow["jobs"]["validate"]["steps"]
    runs = " ".join(str(step.get("run", "")) for step in steps)
    assert "--hevval-report=html,json,md" in runs
    assert "GITHUB_STEP_SUMMARY" in runs
    assert any(str(step.get("uses", "")).startswith("actions/upload-artifact") for step in steps)

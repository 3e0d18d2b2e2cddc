"""The shipped workflow, as a team deploys it: copied unchanged into a model repository and run
the way a GitHub runner runs it (``tests/github_runner.py``), through the sequence a team
lives: main's first run, the first baseline, pull requests that regress and improve, a re-run,
a regression merged, and main's versions over time."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from tests.github_runner import Event, Job, Origin, run_workflow

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "example_project"
WORKFLOW = EXAMPLE / ".github" / "workflows" / "validate.yml"

pytestmark = pytest.mark.slow

#: A folder to keep each job's summary in (unset: none kept).
SUMMARIES_ENV = "HEVVAL_CI_SUMMARIES"

#: The install line is the one thing a team edits; here the plugin under test is already
#: installed, and pip must not reach for an index.
INSTALLED = {
    "HEVVAL_REQUIREMENT": "pytest-hevval",
    "PIP_NO_INDEX": "1",
    "PIP_DISABLE_PIP_VERSION_CHECK": "1",
}

SPEC = """\
name: i3 trip A01
reference: {path: ../data/TripA01.parquet, time: "Time [s]"}
model:
  callable: "models.ev:simulate"
  params: {version: 2}
  inputs: ["Elevation [m]", "Heating Power CAN [kW]", "AirCon Power [kW]"]
  driven_by: ["Velocity [km/h]", "SoC [%]"]
alignment: {max_lag_s: 5}
thresholds: {lag_correlation: 0.9, mae: 0.95, rms: 0.93}
min_phi: 0.9
sets:
  - signal: E_batt
    ref: "integrate(`Battery Voltage [V]` * `Battery Current [A]`) / -3.6e6"
    sim: E_batt
    unit: kWh
    children:
      - signal: P_batt
        ref: "`Battery Voltage [V]` * `Battery Current [A]` / -1000"
        sim: P_batt
        unit: kW
  - {signal: SoC, ref: "SoC [%]", sim: SoC, unit: "%"}
"""


def _model_repository(folder: Path) -> Path:
    """A model repository as a team has one: specs, a model, its measured data, the workflow
    copied unchanged."""
    (folder / "specs").mkdir(parents=True)
    (folder / "data").mkdir()
    (folder / "specs" / "trip.hevval.yaml").write_text(SPEC)
    shutil.copytree(
        EXAMPLE / "models",
        folder / "models",
        ignore=shutil.ignore_patterns("__pycache__", "camry*"),
    )
    shutil.copy(EXAMPLE / "data" / "i3" / "TripA01.parquet", folder / "data")
    (folder / "pytest.ini").write_text(
        "[pytest]\nhevval_files = *.hevval.yaml\ntestpaths = specs\n"
    )
    (folder / ".gitignore").write_text(".hevval/\n__pycache__/\n")
    workflows = folder / ".github" / "workflows"
    workflows.mkdir(parents=True)
    shutil.copy(WORKFLOW, workflows / "validate.yml")
    return folder


def _set_capacity(origin: Origin, factor: float) -> None:
    """Change the model: its battery capacity, as a fraction of the fitted one."""
    path = origin.clone / "models" / "ev_params.json"
    params = json.loads(path.read_text())
    fitted = json.loads((EXAMPLE / "models" / "ev_params.json").read_text())
    params["versions"]["2"]["params"]["capacity_ah"] = (
        fitted["versions"]["2"]["params"]["capacity_ah"] * factor
    )
    path.write_text(json.dumps(params, indent=2))


class _GitHub:
    """The repository on GitHub and the runs of its workflow."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.origin = Origin.create(root, _model_repository(root / "files"))
        self.runs = 0
        self.prs = 0

    def _run(self, event: Event, **kwargs: Any) -> Job:
        job = run_workflow(
            self.origin.clone / ".github" / "workflows" / "validate.yml",
            self.origin,
            event,
            self.root / "runner",
            env_overrides=INSTALLED,
            **kwargs,
        )
        keep = os.environ.get(SUMMARIES_ENV)
        if keep:
            # The summaries docs/history.md quotes come from here.
            name = f"{self.runs:02d}-{event.name}-{event.attempt}.md"
            Path(keep).mkdir(parents=True, exist_ok=True)
            (Path(keep) / name).write_text(job.summary, encoding="utf-8")
        return job

    def _next_id(self) -> int:
        self.runs += 1
        return 1000 + self.runs

    def push_main(self, message: str) -> Job:
        self.origin.switch("main")
        sha = self.origin.commit(message)
        self.origin.push("main")
        return self._run(Event.push(sha, self._next_id()))

    def dispatch(self, **inputs: Any) -> Job:
        sha = self.origin.tip("refs/heads/main")
        assert sha is not None
        return self._run(Event.dispatch(sha, self._next_id(), **inputs))

    def pull_request(self, branch: str, message: str) -> tuple[Job, Event]:
        """Open a pull request from ``branch`` (already switched to and changed)."""
        head = self.origin.commit(message)
        self.origin.push(branch)
        self.prs += 1
        merge = self.origin.pull_request_merge(self.prs, head)
        event = Event.pull(self.prs, merge, head, branch, self._next_id())
        return self._run(event), event

    def rerun(self, event: Event) -> Job:
        return self._run(event.rerun())

    def history(self) -> list[str]:
        return [n for n in self.origin.files_at("refs/heads/hevval-history") if n.endswith(".json")]

    def records(self) -> list[dict[str, Any]]:
        out = []
        for name in sorted(self.history()):
            text = subprocess.run(
                ["git", "show", f"refs/heads/hevval-history:{name}"],
                cwd=self.origin.bare,
                capture_output=True,
                text=True,
                check=True,
            ).stdout
            out.append(json.loads(text))
        return out


def _headline(job: Job) -> str:
    lines = [line for line in job.summary.splitlines() if line.startswith("#")]
    assert lines, job.log
    return lines[0]


@pytest.mark.deployment
def test_the_workflow_gates_pull_requests_against_mains_accepted_history(tmp_path: Path) -> None:
    hub = _GitHub(tmp_path)
    # Main's model starts with a battery 2 % larger than the fitted one.
    _set_capacity(hub.origin, 1.02)

    # 1. main's first run: no baseline yet, and none is made behind the team's back.
    first = hub.push_main("Model v1 on main")
    assert not first.passed
    assert "Run workflow" in first.summary, first.log
    assert "accept" in first.summary
    assert hub.origin.tip("refs/heads/hevval-history") is None

    # 2. the first baseline is an explicit act: a manual run with "accept".
    baseline = hub.dispatch(accept=True)
    assert baseline.passed, baseline.log
    assert len(hub.history()) == 1
    assert hub.records()[-1]["accepted"] is True

    # 3. main again: compared with the baseline, nothing changed, recorded and accepted.
    again = hub.push_main("Docs only")
    assert again.passed, again.log
    assert len(hub.history()) == 2
    assert hub.records()[-1]["accepted"] is True
    # The model beats its thresholds: the ratchet's sidecar is offered for review, not pushed
    # to main.
    ratchet = hub.origin.files_at("refs/heads/hevval-ratchet")
    assert "specs/trip.hevval.thresholds.yaml" in ratchet
    assert "specs/trip.hevval.thresholds.yaml" not in hub.origin.files_at("refs/heads/main")
    assert any(call["args"][:2] == ["pr", "create"] for call in again.gh_calls)

    # 4. a pull request that lowers the capacity to 95 % of the fitted one: fails, naming the
    #    signal, in the summary and the comment.
    hub.origin.switch("smaller-battery", create=True)
    _set_capacity(hub.origin, 0.95)
    regressing, regressing_event = hub.pull_request("smaller-battery", "Capacity -7 %")
    assert not regressing.passed, regressing.log
    assert "SoC: λ4 rms dropped" in regressing.summary
    assert "❌" in _headline(regressing)
    assert "regression" in _headline(regressing)
    assert len(hub.history()) == 2  # a pull request never writes the history
    comments = [call for call in regressing.gh_calls if call["args"][:2] == ["pr", "comment"]]
    assert comments
    assert "SoC: λ4 rms dropped" in (comments[-1]["body"] or "")
    report = json.loads((regressing.artifacts / "hevval-report" / "report.json").read_text())
    assert report["summary"]["passed"] is False
    junit = (regressing.artifacts / "hevval-report" / "junit.xml").read_text()
    assert 'failures="1"' in junit

    # 5. re-running the failed job gives the same verdict.
    rerun = hub.rerun(regressing_event)
    assert not rerun.passed
    assert _headline(rerun) == _headline(regressing)

    # 6. a pull request that fits the capacity: passes, and says what got better.
    hub.origin.switch("main")
    hub.origin.switch("fitted-battery", create=True)
    _set_capacity(hub.origin, 1.0)
    improving, _ = hub.pull_request("fitted-battery", "Capacity as fitted")
    assert improving.passed, improving.log
    assert "✅" in _headline(improving)
    better = re.search(r"(\d+) better", improving.summary)
    assert better is not None, improving.summary
    assert int(better.group(1)) > 0

    # 7. the regressing pull request merged anyway: main fails, its record is kept but not
    #    accepted, so it does not become the baseline.
    hub.origin.merge("smaller-battery", "Merge smaller-battery")
    merged = hub._run(Event.push(hub.origin.tip("refs/heads/main") or "", hub._next_id()))
    assert not merged.passed, merged.log
    assert len(hub.history()) == 3
    assert hub.records()[-1]["accepted"] is False

    # 8. main again: still compared with the last accepted record, still failing.
    later = hub.push_main("Another commit on main")
    assert not later.passed, later.log
    assert "SoC" in later.summary
    assert hub.records()[-1]["accepted"] is False

    # 9. the team accepts the smaller battery by hand; main passes again after that.
    accepted = hub.dispatch(accept=True)
    assert accepted.passed, accepted.log
    assert hub.records()[-1]["accepted"] is True
    calm = hub.push_main("After acceptance")
    assert calm.passed, calm.log

    # The headlines docs/history.md quotes are the ones these jobs wrote.
    _docs_quote(
        {
            "regressing pull request": regressing,
            "improving pull request": improving,
            "accepting run": accepted,
        }
    )

    # 10. main's versions over time: `hevval history` on the branch shows the trend.
    shown = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest_hevval",
            "history",
            "--history-dir",
            str(_checkout_history(hub, tmp_path / "history-view")),
        ],
        capture_output=True,
        text=True,
    )
    assert shown.returncode == 0, shown.stderr
    versions = {line.split()[2] for line in shown.stdout.splitlines() if re.match(r"\d{4}-", line)}
    assert len(versions) >= 5, shown.stdout


def _normalised(line: str) -> str:
    line = re.sub(r"\b[0-9a-f]{7,40}\b", "<commit>", line)
    return re.sub(r"\d{4}-\d\d-\d\d \d\d:\d\d", "<time>", line)


def _docs_quote(jobs: dict[str, Job]) -> None:
    text = (ROOT / "docs" / "history.md").read_text(encoding="utf-8")
    for name, job in jobs.items():
        found = re.search(rf"<!-- emulated summary: {name} -->\n```markdown\n(.*?)\n", text)
        assert found is not None, f"docs/history.md quotes no summary of the {name}"
        assert _normalised(found.group(1)) == _normalised(_headline(job)), name


def _checkout_history(hub: _GitHub, folder: Path) -> Path:
    subprocess.run(
        ["git", "clone", "--quiet", "--branch", "hevval-history", hub.origin.url, str(folder)],
        check=True,
    )
    return folder


def test_the_docs_show_the_shipped_workflow() -> None:
    """Every workflow excerpt in the docs and the README is the shipped file's own text."""
    shipped = [line.strip() for line in WORKFLOW.read_text().splitlines()]
    pages = [ROOT / "README.md", ROOT / "docs" / "quickstart.md", ROOT / "docs" / "history.md"]
    checked = 0
    for page in pages:
        for block in re.findall(r"```yaml\n(.*?)```", page.read_text(), re.S):
            lines = [line.strip() for line in block.splitlines() if line.strip()]
            if not any(
                line.startswith(("- name:", "run:", "uses:", "on:", "HEVVAL_")) for line in lines
            ):
                continue  # not a workflow excerpt (a spec, a sidecar)
            checked += 1
            for line in lines:
                if line.startswith("#") or line == "...":
                    continue
                assert line in shipped, f"{page.name}: {line!r} is not in validate.yml"
    assert checked >= 3


def test_the_workflow_parses_as_github_reads_it() -> None:
    document = yaml.safe_load(WORKFLOW.read_text())
    triggers = document[True]
    assert set(triggers) == {"pull_request", "push", "workflow_dispatch"}
    assert document["permissions"] == {"contents": "write", "pull-requests": "write"}


def _bash_function(script: str, name: str) -> str:
    """The body of the bash function ``name`` in ``script``, its lines stripped."""
    found = re.search(rf"^{name}\(\) {{\n(.*?)\n}}$", script, re.S | re.M)
    assert found is not None, f"no function {name}() in the script"
    return "\n".join(line.strip() for line in found.group(1).splitlines() if line.strip())


def test_ci_runs_the_readme_test_command_verbatim() -> None:
    """What a developer runs to test the project is what CI runs (``.ci/run``)."""
    section = (ROOT / "README.md").read_text(encoding="utf-8").split("## Run the tests", 1)[1]
    block = re.search(r"```bash\n(.*?)\n```", section, re.S)
    assert block is not None, "README.md's 'Run the tests' shows no bash block"
    command = block.group(1).strip()
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert _bash_function(ci, "readme_tests") == command
    assert re.search(r'^step "README test command" readme_tests$', ci, re.M), ci

"""An emulation of a GitHub Actions runner, for testing the workflow files the project ships.

It runs a workflow file as GitHub does, closely enough to show whether the file does its job
when copied into a model repository: each job starts from a fresh shallow clone of an origin
repository at the event's commit (``actions/checkout``), with GitHub's environment variables,
a clean home folder (no git identity), the ``run:`` steps read from the YAML and run in order
by bash as the runner runs them (``bash -e``), ``if:`` conditions and ``${{ }}`` expressions
evaluated, the step summary collected, artifacts kept, and ``gh`` answered by a stand-in that
records what it was asked. Pushes go to the origin through git; the origin refuses pushes from
pull-request jobs, as a fork's read-only token would.

Only what the project's workflows use is emulated; anything else (an unknown action, an
expression outside the subset) raises :class:`Unsupported`, so a test fails rather than
passing over a step it did not run.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "Event",
    "Job",
    "Origin",
    "Unsupported",
    "run_workflow",
]


class Unsupported(Exception):
    """The workflow uses something this emulation does not run."""


# --- the origin repository (GitHub's side) ------------------------------------------------

_PRE_RECEIVE = """#!/bin/sh
# A pull request's job may read but never push (a fork's token is read-only, and the
# workflow must not rely on a pull request writing anything).
if [ "$GITHUB_EVENT_NAME" = "pull_request" ]; then
    echo "emulated GitHub: a pull request's job may not push" >&2
    exit 1
fi
exit 0
"""


def git(*args: str, cwd: Path, env: Mapping[str, str] | None = None) -> str:
    done = subprocess.run(
        ["git", *args],
        cwd=cwd,
        env=dict(env) if env is not None else None,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise RuntimeError(f"git {' '.join(args)} failed in {cwd}:\n{done.stdout}{done.stderr}")
    return done.stdout.strip()


_DEVELOPER = {
    "GIT_AUTHOR_NAME": "Dev",
    "GIT_AUTHOR_EMAIL": "dev@example.com",
    "GIT_COMMITTER_NAME": "Dev",
    "GIT_COMMITTER_EMAIL": "dev@example.com",
}


@dataclass
class Origin:
    """A bare repository standing for the model repository on GitHub, and a developer's
    clone of it to commit and push from."""

    bare: Path
    clone: Path

    @classmethod
    def create(cls, root: Path, files: Path) -> Origin:
        bare = root / "origin.git"
        git("init", "--quiet", "--bare", "--initial-branch=main", str(bare), cwd=root)
        hook = bare / "hooks" / "pre-receive"
        hook.write_text(_PRE_RECEIVE)
        hook.chmod(0o755)
        clone = root / "developer"
        shutil.copytree(files, clone)
        git("init", "--quiet", "--initial-branch=main", cwd=clone)
        git("remote", "add", "origin", cls.url_of(bare), cwd=clone)
        origin = cls(bare, clone)
        origin.commit("Model v1")
        origin.push("main")
        return origin

    @staticmethod
    def url_of(bare: Path) -> str:
        # file:// so that shallow fetches are shallow, as they are from GitHub.
        return bare.resolve().as_uri()

    @property
    def url(self) -> str:
        return self.url_of(self.bare)

    def _env(self) -> dict[str, str]:
        return {**os.environ, **_DEVELOPER}

    def commit(self, message: str) -> str:
        git("add", "-A", cwd=self.clone)
        git("commit", "--quiet", "--allow-empty", "-m", message, cwd=self.clone, env=self._env())
        return git("rev-parse", "HEAD", cwd=self.clone)

    def switch(self, branch: str, *, create: bool = False) -> None:
        git("switch", "--quiet", *(["-c"] if create else []), branch, cwd=self.clone)

    def push(self, branch: str) -> str:
        git(
            "push",
            "--quiet",
            "origin",
            f"{branch}:refs/heads/{branch}",
            cwd=self.clone,
            env=self._env(),
        )
        return git("rev-parse", branch, cwd=self.clone)

    def merge(self, branch: str, message: str) -> str:
        """Merge a pull request's branch into main, as the merge button does."""
        self.switch("main")
        git("merge", "--quiet", "--no-ff", "-m", message, branch, cwd=self.clone, env=self._env())
        return self.push("main")

    def pull_request_merge(self, number: int, head: str) -> str:
        """The commit GitHub tests a pull request at: its head merged into the base's tip,
        published as ``refs/pull/N/merge``."""
        git("fetch", "--quiet", "origin", cwd=self.clone)
        main = git("rev-parse", "refs/remotes/origin/main", cwd=self.clone)
        tree_env = self._env()
        git(
            "push",
            "--quiet",
            "origin",
            f"{head}:refs/pull/{number}/head",
            cwd=self.clone,
            env=tree_env,
        )
        scratch = self.clone.parent / f"merge-{number}"
        if scratch.exists():
            shutil.rmtree(scratch)
        git("clone", "--quiet", self.url, str(scratch), cwd=self.clone.parent)
        git("fetch", "--quiet", "origin", f"refs/pull/{number}/head", cwd=scratch)
        git("checkout", "--quiet", "--detach", main, cwd=scratch)
        git(
            "merge",
            "--quiet",
            "--no-ff",
            "-m",
            f"Merge {head} into {main}",
            "FETCH_HEAD",
            cwd=scratch,
            env=tree_env,
        )
        merged = git("rev-parse", "HEAD", cwd=scratch)
        git(
            "push",
            "--quiet",
            "--force",
            "origin",
            f"HEAD:refs/pull/{number}/merge",
            cwd=scratch,
            env=tree_env,
        )
        shutil.rmtree(scratch)
        return merged

    def tip(self, ref: str) -> str | None:
        done = subprocess.run(
            ["git", "rev-parse", "--verify", "--quiet", ref],
            cwd=self.bare,
            capture_output=True,
            text=True,
        )
        return done.stdout.strip() or None

    def files_at(self, ref: str) -> list[str]:
        return git("ls-tree", "--name-only", "-r", ref, cwd=self.bare).splitlines()


# --- events and jobs -----------------------------------------------------------------------


@dataclass(frozen=True)
class Event:
    """What triggered a run: ``push``, ``pull_request`` or ``workflow_dispatch``."""

    name: str
    ref: str
    sha: str
    run_id: int
    attempt: int = 1
    inputs: Mapping[str, Any] = field(default_factory=dict)
    pull_request: Mapping[str, Any] | None = None

    @classmethod
    def push(cls, sha: str, run_id: int, branch: str = "main") -> Event:
        return cls("push", f"refs/heads/{branch}", sha, run_id)

    @classmethod
    def dispatch(cls, sha: str, run_id: int, **inputs: Any) -> Event:
        return cls("workflow_dispatch", "refs/heads/main", sha, run_id, inputs=inputs)

    @classmethod
    def pull(cls, number: int, merge_sha: str, head_sha: str, head_ref: str, run_id: int) -> Event:
        payload = {
            "number": number,
            "head": {"sha": head_sha, "ref": head_ref},
            "base": {"ref": "main"},
        }
        return cls(
            "pull_request",
            f"refs/pull/{number}/merge",
            merge_sha,
            run_id,
            pull_request=payload,
        )

    def rerun(self) -> Event:
        return dataclasses.replace(self, attempt=self.attempt + 1)


@dataclass
class Step:
    name: str
    outcome: str  # success, failure, skipped
    output: str


@dataclass
class Job:
    """What a job left: each step's outcome and output, the job summary, the artifacts,
    and what ``gh`` was asked."""

    event: Event
    steps: list[Step]
    summary: str
    artifacts: Path
    gh_calls: list[dict[str, Any]]

    @property
    def passed(self) -> bool:
        return all(step.outcome != "failure" for step in self.steps)

    def step(self, name: str) -> Step:
        return next(step for step in self.steps if step.name == name)

    @property
    def log(self) -> str:
        return "\n".join(f"--- {s.name} [{s.outcome}]\n{s.output}" for s in self.steps)


# --- expressions ---------------------------------------------------------------------------

_TOKEN = re.compile(
    r"\s*(?:(?P<string>'(?:[^']|'')*')|(?P<number>\d+(?:\.\d+)?)|(?P<op>==|!=|&&|\|\||!|\(|\)|,)"
    r"|(?P<name>[A-Za-z_][A-Za-z0-9_\-]*(?:\.[A-Za-z_][A-Za-z0-9_\-]*)*))"
)


class _Expression:
    """GitHub's expression syntax, the subset the workflows use: literals, context paths,
    ``== != && || !``, parentheses and the status functions."""

    def __init__(self, text: str, contexts: Mapping[str, Any], status: str) -> None:
        self.tokens: list[tuple[str, str]] = []
        position = 0
        text = text.strip()
        while position < len(text):
            found = _TOKEN.match(text, position)
            if found is None or found.end() == position:
                raise Unsupported(f"expression {text!r}: cannot read at {text[position:]!r}")
            kind = found.lastgroup or ""
            self.tokens.append((kind, found.group(kind)))
            position = found.end()
        self.at = 0
        self.contexts = contexts
        self.status = status

    def value(self) -> Any:
        result = self._or()
        if self.at != len(self.tokens):
            raise Unsupported(f"expression: unexpected {self.tokens[self.at][1]!r}")
        return result

    def _peek(self) -> str | None:
        return self.tokens[self.at][1] if self.at < len(self.tokens) else None

    def _or(self) -> Any:
        left = self._and()
        while self._peek() == "||":
            self.at += 1
            right = self._and()
            left = left if _truthy(left) else right
        return left

    def _and(self) -> Any:
        left = self._compare()
        while self._peek() == "&&":
            self.at += 1
            right = self._compare()
            left = right if _truthy(left) else left
        return left

    def _compare(self) -> Any:
        left = self._unary()
        while self._peek() in ("==", "!="):
            op = self.tokens[self.at][1]
            self.at += 1
            right = self._unary()
            equal = _loose_equal(left, right)
            left = equal if op == "==" else not equal
        return left

    def _unary(self) -> Any:
        if self._peek() == "!":
            self.at += 1
            return not _truthy(self._unary())
        return self._primary()

    def _primary(self) -> Any:
        if self.at >= len(self.tokens):
            raise Unsupported("expression ends too early")
        kind, text = self.tokens[self.at]
        self.at += 1
        if text == "(":
            inner = self._or()
            if self._peek() != ")":
                raise Unsupported("expression: missing ')'")
            self.at += 1
            return inner
        if kind == "string":
            return text[1:-1].replace("''", "'")
        if kind == "number":
            return float(text)
        if kind != "name":
            raise Unsupported(f"expression: unexpected {text!r}")
        if self._peek() == "(":
            self.at += 1
            if self._peek() != ")":
                raise Unsupported(f"function {text}() with arguments")
            self.at += 1
            return self._function(text)
        if text in ("true", "false"):
            return text == "true"
        if text == "null":
            return None
        value: Any = self.contexts
        for part in text.split("."):
            value = value.get(part) if isinstance(value, Mapping) else None
        return value

    def _function(self, name: str) -> bool:
        if name == "always":
            return True
        if name == "success":
            return self.status == "success"
        if name == "failure":
            return self.status == "failure"
        if name == "cancelled":
            return False
        raise Unsupported(f"function {name}()")


def _truthy(value: Any) -> bool:
    return value not in (None, False, 0, 0.0, "")


def _loose_equal(left: Any, right: Any) -> bool:
    if isinstance(left, str) and isinstance(right, str):
        return left.lower() == right.lower()
    return bool(left == right)


def _evaluate(text: str, contexts: Mapping[str, Any], status: str) -> Any:
    return _Expression(text, contexts, status).value()


def _substitute(text: str, contexts: Mapping[str, Any], status: str) -> str:
    def one(found: re.Match[str]) -> str:
        value = _evaluate(found.group(1), contexts, status)
        if value is None:
            return ""
        if isinstance(value, bool):
            return "true" if value else "false"
        if isinstance(value, float) and value.is_integer():
            return str(int(value))
        return str(value)

    return re.sub(r"\$\{\{(.*?)\}\}", one, text)


def _condition(step: Mapping[str, Any], contexts: Mapping[str, Any], status: str) -> bool:
    text = str(step.get("if", "success()")).strip()
    if text.startswith("${{") and text.endswith("}}"):
        text = text[3:-2]
    if not re.search(r"\b(always|success|failure|cancelled)\(\)", text):
        # GitHub adds success() to a condition that names no status function.
        text = f"success() && ({text})"
    return _truthy(_evaluate(text, contexts, status))


# --- the runner ----------------------------------------------------------------------------

_GH = """#!/usr/bin/env python3
import json, os, sys
args = sys.argv[1:]
body = None
if "--body-file" in args:
    with open(args[args.index("--body-file") + 1], encoding="utf-8") as handle:
        body = handle.read()
with open(os.environ["EMULATED_GH_LOG"], "a", encoding="utf-8") as log:
    log.write(json.dumps({"args": args, "body": body}) + "\\n")
if "--edit-last" in args and not os.environ.get("EMULATED_GH_HAS_COMMENT"):
    print("no comments found for current user", file=sys.stderr)
    sys.exit(1)
"""

#: Variables of the test process that a runner would not have.
_KEPT_FROM_HOST = (
    "PATH",
    "LANG",
    "LC_ALL",
    "PYTHONPATH",
    "NUMBA_CACHE_DIR",
    "TMPDIR",
    "VIRTUAL_ENV",
    "PYTHONHASHSEED",
)


def run_workflow(
    workflow: Path,
    origin: Origin,
    event: Event,
    root: Path,
    *,
    job: str = "validate",
    env_overrides: Mapping[str, str] | None = None,
    gh_has_comment: bool = False,
) -> Job:
    """Run one job of ``workflow`` for ``event`` in a new folder under ``root``."""
    document = yaml.safe_load(workflow.read_text(encoding="utf-8"))
    triggers = document.get(True, document.get("on"))  # YAML 1.1 reads a bare `on` as True
    if event.name not in (triggers or {}):
        raise Unsupported(f"{workflow.name} does not run on {event.name}")
    spec = document["jobs"][job]
    folder = root / f"run-{event.run_id}-{event.attempt}-{event.name}"
    workspace = folder / "workspace"
    home = folder / "home"
    temp = folder / "temp"
    tools = folder / "tools"
    artifacts = folder / "artifacts"
    for made in (workspace, home, temp, tools, artifacts):
        made.mkdir(parents=True)
    gh = tools / "gh"
    gh.write_text(_GH.replace("/usr/bin/env python3", sys.executable, 1))
    gh.chmod(0o755)
    gh_log = folder / "gh.jsonl"
    summary_file = temp / "step_summary"
    env_file = temp / "github_env"
    event_file = temp / "event.json"
    payload: dict[str, Any] = {}
    if event.pull_request is not None:
        payload["pull_request"] = dict(event.pull_request)
        payload["number"] = event.pull_request["number"]
    if event.inputs:
        payload["inputs"] = dict(event.inputs)
    event_file.write_text(json.dumps(payload))

    ref_name = event.ref.removeprefix("refs/heads/")
    if event.pull_request is not None:
        ref_name = f"{event.pull_request['number']}/merge"
    github: dict[str, Any] = {
        "event_name": event.name,
        "ref": event.ref,
        "ref_name": ref_name,
        "sha": event.sha,
        "run_id": str(event.run_id),
        "run_attempt": str(event.attempt),
        "repository": "team/model",
        "token": "emulated-token",
        "workspace": str(workspace),
        "base_ref": event.pull_request["base"]["ref"] if event.pull_request else "",
        "head_ref": event.pull_request["head"]["ref"] if event.pull_request else "",
        "event": payload,
    }
    base_env = {name: os.environ[name] for name in _KEPT_FROM_HOST if name in os.environ}
    base_env["PATH"] = (
        f"{tools}{os.pathsep}{Path(sys.executable).parent}{os.pathsep}" + base_env.get("PATH", "")
    )
    base_env.update(
        {
            "HOME": str(home),
            "GIT_CONFIG_NOSYSTEM": "1",
            "CI": "true",
            "GITHUB_ACTIONS": "true",
            "GITHUB_EVENT_NAME": event.name,
            "GITHUB_EVENT_PATH": str(event_file),
            "GITHUB_REF": event.ref,
            "GITHUB_REF_NAME": ref_name,
            "GITHUB_REF_TYPE": "branch",
            "GITHUB_SHA": event.sha,
            "GITHUB_BASE_REF": github["base_ref"],
            "GITHUB_HEAD_REF": github["head_ref"],
            "GITHUB_RUN_ID": str(event.run_id),
            "GITHUB_RUN_ATTEMPT": str(event.attempt),
            "GITHUB_REPOSITORY": "team/model",
            "GITHUB_WORKSPACE": str(workspace),
            "GITHUB_STEP_SUMMARY": str(summary_file),
            "GITHUB_ENV": str(env_file),
            "RUNNER_TEMP": str(temp),
            "RUNNER_OS": "Linux",
            "EMULATED_GH_LOG": str(gh_log),
        }
    )
    if gh_has_comment:
        base_env["EMULATED_GH_HAS_COMMENT"] = "1"
    workflow_env = {str(k): str(v) for k, v in (document.get("env") or {}).items()}
    workflow_env.update(env_overrides or {})
    contexts: dict[str, Any] = {"github": github, "inputs": dict(event.inputs)}
    job_env = {str(k): str(v) for k, v in (spec.get("env") or {}).items()}

    steps: list[Step] = []
    summary: list[str] = []
    status = "success"
    for index, step in enumerate(spec["steps"]):
        name = str(step.get("name") or step.get("uses") or f"step {index + 1}")
        contexts["env"] = {**workflow_env, **job_env}
        if not _condition(step, contexts, status):
            steps.append(Step(name, "skipped", ""))
            continue
        step_env = {
            str(k): _substitute(str(v), contexts, status)
            for k, v in (step.get("env") or {}).items()
        }
        env = {**base_env, **contexts["env"], **step_env}
        env.update(_read_env_file(env_file))
        summary_file.write_text("")
        if "uses" in step:
            outcome, output = _action(
                str(step["uses"]),
                step.get("with") or {},
                contexts,
                status,
                origin,
                event,
                workspace,
                artifacts,
                env,
            )
        else:
            script = _substitute(str(step["run"]), contexts, status)
            outcome, output = _shell(script, step.get("shell"), workspace, env, temp)
        summary.append(summary_file.read_text(encoding="utf-8"))
        steps.append(Step(name, outcome, output))
        if outcome == "failure":
            status = "failure"
    calls = []
    if gh_log.exists():
        calls = [json.loads(line) for line in gh_log.read_text(encoding="utf-8").splitlines()]
    return Job(event, steps, "".join(summary), artifacts, calls)


def _read_env_file(path: Path) -> dict[str, str]:
    if not path.exists():
        return {}
    found = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if "=" in line:
            key, value = line.split("=", 1)
            found[key] = value
    return found


def _shell(
    script: str, shell: str | None, workspace: Path, env: Mapping[str, str], temp: Path
) -> tuple[str, str]:
    path = temp / "step.sh"
    path.write_text(script, encoding="utf-8")
    if shell in (None, ""):
        command = ["bash", "-e", str(path)]  # the runner's default shell on Linux
    elif shell == "bash":
        command = ["bash", "--noprofile", "--norc", "-eo", "pipefail", str(path)]
    else:
        raise Unsupported(f"shell {shell!r}")
    done = subprocess.run(
        command,
        cwd=workspace,
        env=dict(env),
        capture_output=True,
        text=True,
        stdin=subprocess.DEVNULL,
    )
    return ("success" if done.returncode == 0 else "failure"), done.stdout + done.stderr


def _action(
    uses: str,
    given: Mapping[str, Any],
    contexts: Mapping[str, Any],
    status: str,
    origin: Origin,
    event: Event,
    workspace: Path,
    artifacts: Path,
    env: Mapping[str, str],
) -> tuple[str, str]:
    name = uses.split("@", 1)[0]
    options = {str(k): _substitute(str(v), contexts, status) for k, v in given.items()}
    if name == "actions/checkout":
        depth = int(options.get("fetch-depth", "1"))
        git("init", "--quiet", cwd=workspace, env=env)
        git("remote", "add", "origin", origin.url, cwd=workspace, env=env)
        fetch = ["fetch", "--quiet", "--no-tags"]
        if depth > 0:
            fetch.append(f"--depth={depth}")
        git(*fetch, "origin", f"+{event.sha}:refs/remotes/origin/checkout", cwd=workspace, env=env)
        git("checkout", "--quiet", "--detach", event.sha, cwd=workspace, env=env)
        return "success", f"checked out {event.sha} ({event.ref})"
    if name == "actions/setup-python":
        return "success", f"python {sys.version.split()[0]} (the test's interpreter)"
    if name == "actions/upload-artifact":
        source = workspace / options["path"]
        if not source.exists():
            if options.get("if-no-files-found", "warn") == "error":
                return "failure", f"no files at {options['path']}"
            return "success", f"warning: no files at {options['path']}"
        shutil.copytree(source, artifacts / options.get("name", "artifact"), dirs_exist_ok=True)
        return "success", f"uploaded {options['path']}"
    raise Unsupported(f"action {uses}")

"""The hostile inputs of the third round (issue 50), each with the family it stands for: run
as ``hevval`` in a child process bounded in time and memory (``tests/test_hostile.py``), or
through pytester where the pytest front end is the one at stake.

Each ``hevval`` here is a child process of its own, with its own folder, environment, output
files, memory limit and time limit, as in ``tests/test_hostile.py``; but the children are
forked from one server process that has already imported the third-party libraries every
command imports (numpy, pandas, scipy, pyarrow, PyYAML, pytest). Starting an interpreter and
importing those took about 1 s of the 2 s of CPU each command cost; this file runs about fifty
commands. The package itself is imported afresh in every child, as ``python -m pytest_hevval``
imports it, and exits as that does (the interpreter's own handling of SystemExit and of an
uncaught exception, exit handlers included). A command whose environment differs in what an
interpreter reads only when it starts (``PYTHON*``, the locale) runs in a fresh interpreter.
"""

from __future__ import annotations

import hashlib
import json
import locale
import os
import subprocess
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tests import test_hostile
from tests.test_hostile import MEMORY_LIMIT, SPEC, TIME_LIMIT_S, _clear_error

#: The folder of test_hostile: a spec, ref.csv and sim.csv (the model is off by 0.01).
project = test_hostile.project

#: Imported by the fork server before it forks: the third-party libraries every command loads.
PRELOADED = (
    "numpy",
    "pandas",
    "scipy.fft",
    "scipy.linalg",
    "scipy.signal",
    "scipy.stats",
    "yaml",
    "pytest",
    "pyarrow.parquet",
    "jinja2",
)

#: The server: reads one command a line (JSON), forks a child for it and answers with its
#: exit code. The child's path never returns into the loop: `python -m pytest_hevval` raises
#: SystemExit, or an exception, through this script's top level, so the interpreter ends the
#: child exactly as it ends that command.
FORK_SERVER = """\
import importlib, json, os, resource, runpy, signal, sys, time
for name in json.loads(sys.argv[1]):
    try:
        importlib.import_module(name)
    except ImportError:
        pass
requests = os.fdopen(os.dup(0), "r", encoding="utf-8")
replies = os.fdopen(os.dup(1), "w", encoding="utf-8")
os.dup2(2, 1)
null = os.open(os.devnull, os.O_RDONLY)
os.dup2(null, 0)
os.close(null)
for line in requests:
    case = json.loads(line)
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid == 0:
        requests.close()
        replies.close()
        os.chdir(case["cwd"])
        os.environ.clear()
        os.environ.update(case["env"])
        for fd, path in ((1, case["stdout"]), (2, case["stderr"])):
            out = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            os.dup2(out, fd)
            os.close(out)
        resource.setrlimit(resource.RLIMIT_AS, (case["memory"], case["memory"]))
        sys.path[0] = os.getcwd()
        sys.argv = ["", *case["argv"]]
        importlib.invalidate_caches()
        runpy.run_module("pytest_hevval", run_name="__main__", alter_sys=True)
        raise SystemExit(0)
    deadline = time.monotonic() + case["seconds"]
    code = None
    while code is None:
        ended, status = os.waitpid(pid, os.WNOHANG)
        if ended:
            code = os.waitstatus_to_exitcode(status)
        elif time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            break
        else:
            time.sleep(0.005)
    replies.write(json.dumps({"returncode": code}) + "\\n")
    replies.flush()
"""

#: What an interpreter reads from its environment only when it starts.
_AT_START = ("PYTHON", "LANG", "LC_")


def _environment() -> dict[str, str]:
    """A command's environment, as ``tests/test_hostile.py`` gives it."""
    return {**os.environ, "PYTHONWARNINGS": "error::RuntimeWarning"}


def _at_start(env: Mapping[str, str]) -> dict[str, str]:
    return {k: v for k, v in env.items() if k.startswith(_AT_START)}


class _ForkServer:
    """One server process (``FORK_SERVER``) for the commands of a test session's worker."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.env = _environment()
        self.log = folder / "server.log"
        with self.log.open("wb") as log:
            self.process = subprocess.Popen(
                [sys.executable, "-c", FORK_SERVER, json.dumps(PRELOADED)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=log,
                cwd=folder,
                env=self.env,
                text=True,
            )
        self.count = 0

    def takes(self, env: Mapping[str, str]) -> bool:
        """Whether a child of this server starts as a fresh interpreter with ``env`` would."""
        return self.process.poll() is None and _at_start(env) == _at_start(self.env)

    def run(self, folder: Path, argv: tuple[str, ...], env: Mapping[str, str]) -> Completed:
        self.count += 1
        out = self.folder / f"{self.count}.out"
        err = self.folder / f"{self.count}.err"
        case = {
            "cwd": str(folder),
            "env": dict(env),
            "argv": list(argv),
            "stdout": str(out),
            "stderr": str(err),
            "memory": MEMORY_LIMIT,
            "seconds": TIME_LIMIT_S,
        }
        assert self.process.stdin is not None
        assert self.process.stdout is not None
        self.process.stdin.write(json.dumps(case) + "\n")
        self.process.stdin.flush()
        reply = self.process.stdout.readline()
        if not reply:
            pytest.fail(f"the fork server ended: {self.log.read_text(errors='replace')[-3000:]}")
        code = json.loads(reply)["returncode"]
        if code is None:
            pytest.fail(f"hevval {' '.join(argv)} did not end within {TIME_LIMIT_S} s")
        command = [sys.executable, "-m", "pytest_hevval", *argv]
        return subprocess.CompletedProcess(command, code, _text(out), _text(err))

    def close(self) -> None:
        self.process.communicate(timeout=TIME_LIMIT_S)


Completed = subprocess.CompletedProcess[str]


def _text(path: Path) -> str:
    """A captured stream as ``subprocess.run(..., text=True)`` decodes it."""
    text = path.read_bytes().decode(locale.getpreferredencoding(False))
    return text.replace("\r\n", "\n").replace("\r", "\n")


_server: _ForkServer | None = None


@pytest.fixture(scope="module", autouse=True)
def _fork_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    global _server
    if not hasattr(os, "fork"):
        yield
        return
    _server = _ForkServer(tmp_path_factory.mktemp("fork-server"))
    yield
    _server.close()
    _server = None


def hevval(folder: Path, *argv: str) -> Completed:
    """``hevval ARGV`` in ``folder``, in a child process bounded in time and memory."""
    env = _environment()
    if _server is None or not _server.takes(env):
        return test_hostile.hevval(folder, *argv)
    return _server.run(folder, argv, env)


def _spec(project: Path, text: str, name: str = "hostile.hevval.yaml") -> str:
    (project / name).write_text(text, encoding="utf-8")
    return name


#: Records written by ``hevval run --history``, by the digest of the files it read. A record
#: names its files relative to the spec and holds no folder, so a record of the same spec and
#: data is the same record wherever it was written.
_RECORDS: dict[str, tuple[str, str]] = {}


def _record(project: Path, **fields: object) -> Path:
    """A history record written by ``hevval run --history``, with ``fields`` replaced. The run
    is made once per set of input files; later calls copy its record."""
    inputs = hashlib.sha256()
    for name in ("hostile.hevval.yaml", "ref.csv", "sim.csv"):
        inputs.update((project / name).read_bytes())
    history = project / ".hevval" / "history"
    if inputs.hexdigest() not in _RECORDS:
        done = hevval(project, "run", "hostile.hevval.yaml", "--history")
        assert done.returncode == 0, done.stderr
        (written,) = history.glob("*.json")
        _RECORDS[inputs.hexdigest()] = (written.name, written.read_text("utf-8"))
    name, text = _RECORDS[inputs.hexdigest()]
    history.mkdir(parents=True, exist_ok=True)
    path = history / name
    assert not path.exists() or path.read_text("utf-8") == text
    record = json.loads(text)
    record.update(fields)
    path.write_text(json.dumps(record), encoding="utf-8")
    assert list(history.glob("*.json")) == [path]
    return path


# -- numbers beyond what float64 holds ----------------------------------------------------------


@pytest.mark.parametrize(
    ("started", "problem"),
    [
        ("9999-12-31T23:59:59-12:00", "outside the years 1 to 9999"),
        ("0001-01-01T00:00:00+14:00", "outside the years 1 to 9999"),
    ],
)
def test_a_history_record_starting_beyond_year_9999_is_skipped_and_named(
    project: Path, started: str, problem: str
) -> None:
    path = _record(project, started_utc=started)
    done = hevval(project, "history")
    assert "Traceback" not in done.stdout + done.stderr, done.stderr
    assert path.name in done.stderr, done.stderr
    assert problem in done.stderr, done.stderr


@pytest.mark.parametrize("key", ["ref_scale", "sim_scale"])
def test_a_scale_that_overflows_the_signal_names_its_key(project: Path, key: str) -> None:
    _spec(project, SPEC.replace("{signal: v}", f"{{signal: v, {key}: 1.0e+308}}"))
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "hostile.hevval.yaml", f"sets[0].{key}", "beyond what float64 holds")


def test_a_time_scale_that_overflows_the_time_names_its_key(project: Path) -> None:
    """Scaled to inf: an error naming the key, and no RuntimeWarning (the child turns warnings
    into errors)."""
    _spec(project, SPEC.replace("{path: sim.csv}", "{path: sim.csv, time_scale: 1.0e+307}"))
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "sim.csv", "time_scale", "outside what float64 holds")


# -- every path the tool writes -----------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ("run", "hostile.hevval.yaml", "--no-history", "--json"),
        ("diagnose", "hostile.hevval.yaml", "--signal", "v", "--json"),
    ],
    ids=["run", "diagnose"],
)
@pytest.mark.parametrize("target", ["out", "new/"], ids=["existing folder", "trailing slash"])
def test_json_output_naming_a_folder_says_so(
    project: Path, argv: tuple[str, ...], target: str
) -> None:
    (project / "out").mkdir()
    done = hevval(project, *argv, target)
    _clear_error(done, "names a folder" if target.endswith("/") else "it is a folder")
    assert "cannot write it: " in done.stderr
    assert done.stderr.count("cannot write") == 1
    assert not (project / "new").exists()


def test_history_and_compare_output_naming_a_folder_say_so_once(project: Path) -> None:
    _record(project)
    (project / "out").mkdir()
    for argv in (
        ("history", "--json", "out"),
        ("compare", "history:latest", "history:latest", "--output", "out"),
    ):
        done = hevval(project, *argv)
        _clear_error(done, "out: cannot write it: it is a folder")
        assert done.stderr.count("cannot write") == 1, done.stderr


# -- a model callable's output in every type --------------------------------------------------

MODELS = """\
import numpy as np
import pandas as pd


def text(frame):
    return pd.DataFrame({"time": frame["time"], "v": [str(x) for x in np.sin(frame["time"])]})


def milliseconds(frame):
    return pd.DataFrame({"t_ms": frame["time"] * 1000, "v": np.sin(frame["time"]) + 0.1})


def datetimes(frame):
    start = pd.Timestamp("2024-01-01T00:00:00Z")
    stamps = start + pd.to_timedelta(frame["time"], unit="s")
    return pd.DataFrame({"time": stamps, "v": np.sin(frame["time"]) + 0.1})


def iso_text(frame):
    start = pd.Timestamp("2024-01-01T00:00:00Z")
    stamps = (start + pd.to_timedelta(frame["time"], unit="s")).dt.strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    return pd.DataFrame({"time": stamps, "v": np.sin(frame["time"]) + 0.1})


def float32(frame):
    t = frame["time"].to_numpy(dtype=np.float32)
    return pd.DataFrame({"time": t, "v": (np.sin(frame["time"]) + 0.1).astype(np.float32)})


def text_time(frame):
    return pd.DataFrame({"time": ["zero", *frame["time"][1:]], "v": np.sin(frame["time"])})
"""


def _callable_spec(
    project: Path, function: str, model_keys: str = "", *, source: str = MODELS, more: str = ""
) -> str:
    """A spec scoring ``v`` of ref.csv against ``models:FUNCTION`` (``source``); ``more``:
    top-level keys besides."""
    (project / "models.py").write_text(source, encoding="utf-8")
    return _spec(
        project,
        "name: hostile\nreference: {path: ref.csv}\n"
        f'model: {{callable: "models:{function}"{model_keys}}}\n'
        f"{more}sets:\n  - {{signal: v}}\n",
    )


def test_a_model_column_of_text_is_named_as_not_numeric(project: Path) -> None:
    spec = _callable_spec(project, "text")
    done = hevval(project, "run", spec, "--no-history")
    _clear_error(done, "column 'v'", "holds objects (text or mixed)", "not numbers")
    assert "no such column" not in done.stderr


@pytest.mark.parametrize(
    ("function", "model_keys"),
    [
        ("milliseconds", ", time: t_ms, time_scale: 0.001"),
        ("datetimes", ""),
        ("iso_text", ""),
        ("float32", ""),
    ],
)
def test_a_model_time_column_is_read_by_the_rule_every_file_is(
    project: Path, function: str, model_keys: str
) -> None:
    """The model is the reference plus 0.1: its MAE is 0.1 whatever type its time has."""
    spec = _callable_spec(project, function, model_keys)
    done = hevval(project, "run", spec, "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stderr
    (signal,) = json.loads((project / "out.json").read_text("utf-8"))["signals"]
    assert signal["mae"] == pytest.approx(0.1, abs=1e-5)


def test_a_model_time_column_with_a_word_names_the_cell(project: Path) -> None:
    spec = _callable_spec(project, "text_time")
    done = hevval(project, "run", spec, "--no-history")
    _clear_error(done, "column 'time'", "non-numeric value 'zero' at index 0")


# -- time stamps no type holds -------------------------------------------------------------------


def test_a_leap_second_is_named_where_it_is(project: Path) -> None:
    start = pd.Timestamp("2016-12-31T23:59:50Z")
    stamps = [
        (start + pd.Timedelta(seconds=0.1 * i)).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-5] + "Z"
        for i in range(200)
    ]
    stamps[100] = "2016-12-31T23:59:60.0Z"
    v = np.sin(np.arange(200) * 0.1)
    pd.DataFrame({"time": stamps, "v": v}).to_csv(project / "ref.csv", index=False)
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "ref.csv:102: column 'time'", "at index 100", "leap second")


# -- text from specs and data reaching a terminal, a CI log or Markdown ------------------------

FORGED = "::error file=evil.py::FORGED"
#: A channel or signal name that would start a workflow command on a line of its own and
#: clear the screen.
HOSTILE_NAME = f"amb\n{FORGED}\x1b[2J\x1b]0;title\x07\u202e"


def _forges(output: str) -> list[str]:
    """Lines that a CI runner would take as a workflow command, and escape sequences."""
    forged = [line for line in output.splitlines() if line.lstrip().startswith(FORGED)]
    return forged + [char for char in "\x1b\x07\u202e" if char in output]


def _hostile_channel(project: Path) -> None:
    t = np.arange(0.0, 30.0, 0.1)
    frame = pd.DataFrame({"t": t, "v": np.sin(t), HOSTILE_NAME: np.cos(t)})
    frame.to_csv(project / "ref.csv", index=False)
    sim = pd.DataFrame({"t": t, "v": np.sin(t) + 0.3 * np.cos(t)})
    sim.to_csv(project / "sim.csv", index=False)


def test_diagnose_in_ci_prints_a_data_header_as_text(
    project: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The header's channel explains the residual, so the diagnosis names it."""
    _hostile_channel(project)
    monkeypatch.setenv("GITHUB_ACTIONS", "true")
    done = hevval(project, "diagnose", "hostile.hevval.yaml", "--signal", "v")
    assert done.returncode == 0, done.stderr
    assert "amb" in done.stdout, done.stdout
    assert _forges(done.stdout + done.stderr) == []


@pytest.mark.parametrize(
    "argv",
    [
        ("run", "hostile.hevval.yaml", "--no-history", "--compare"),
        ("history",),
        ("compare", "history:latest", "hostile.json"),
    ],
    ids=["run --compare", "history", "compare"],
)
def test_a_model_version_from_history_is_printed_as_text(
    project: Path, monkeypatch: pytest.MonkeyPatch, argv: tuple[str, ...]
) -> None:
    """A record written by another tool, whose model version and spec name forge commands."""
    _record(project, model_version=HOSTILE_NAME)
    assert hevval(project, "run", "hostile.hevval.yaml", "--json", "hostile.json").returncode == 0
    monkeypatch.setenv("GITHUB_ACTIONS", "true")
    done = hevval(project, *argv)
    assert "amb" in done.stdout, done.stdout + done.stderr
    assert _forges(done.stdout + done.stderr) == []


def test_pytest_prints_a_model_version_from_history_as_text(
    pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch
) -> None:
    t = np.arange(0.0, 30.0, 0.1)
    pd.DataFrame({"t": t, "v": np.sin(t)}).to_csv(pytester.path / "ref.csv", index=False)
    pd.DataFrame({"t": t, "v": np.sin(t)}).to_csv(pytester.path / "sim.csv", index=False)
    _spec(pytester.path, SPEC)
    _record(pytester.path, model_version=HOSTILE_NAME)
    monkeypatch.setenv("GITHUB_ACTIONS", "true")
    result = pytester.runpytest_subprocess("--hevval", "--hevval-compare", "-p", "no:cacheprovider")
    output = result.stdout.str() + result.stderr.str()
    assert result.ret == 0, output
    assert "amb" in output, output
    assert _forges(output) == []


def test_compare_markdown_holds_no_raw_html_or_broken_code_span(project: Path) -> None:
    for version in ("<img src=a onerror=alert(2)>", "v2`<b>`|"):
        argv = ("run", "hostile.hevval.yaml", "--history", "--model-version", version)
        assert hevval(project, *argv).returncode == 0
    done = hevval(project, "compare", "history:previous", "history:latest", "--format", "md")
    assert done.returncode == 0, done.stderr
    assert "<img" not in done.stdout, done.stdout
    assert "<b>" not in done.stdout, done.stdout
    assert "&lt;img src=a" in done.stdout, done.stdout
    for line in done.stdout.splitlines():
        assert line.replace("\\`", "").count("`") % 2 == 0, line


def test_an_output_stream_that_cannot_encode_phi(
    project: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PYTHONIOENCODING", "ascii")
    for argv in (("run", "hostile.hevval.yaml", "--no-history", "--details"),):
        done = hevval(project, *argv)
        assert done.returncode == 0, done.stderr
        assert "\\u03a6" in done.stdout, done.stdout


# -- encodings a file announces -------------------------------------------------------------------


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-32"])
def test_a_csv_with_a_byte_order_mark_is_read_in_its_encoding(project: Path, encoding: str) -> None:
    text = (project / "ref.csv").read_text("utf-8")
    bom = {"utf-16-be": "\ufeff"}.get(encoding, "")
    (project / "ref.csv").write_bytes((bom + text).encode(encoding))
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stderr
    (signal,) = json.loads((project / "out.json").read_text("utf-8"))["signals"]
    assert signal["mae"] == pytest.approx(0.01, abs=1e-9)


# -- names that mean something to a library ---------------------------------------------------


def test_a_plot_of_a_signal_named_with_maths_markup(project: Path) -> None:
    pytest.importorskip("matplotlib")
    name = json.dumps("fuel $_$ rate")
    _spec(project, SPEC.replace("{signal: v}", f"{{signal: {name}, ref: v, sim: v}}"))
    _record(project, model_version="$\\frac{1}{$")
    done = hevval(project, "history", "--signal", "fuel $_$ rate", "--plot", "trend.png")
    assert done.returncode == 0, done.stderr
    assert (project / "trend.png").stat().st_size > 0


def test_a_rate_limit_on_a_misspelt_channel_says_which_was_meant(project: Path) -> None:
    quality = "data_quality: {action: error, rate_limits: {w: 0.001}}\n"
    _spec(project, SPEC.replace("sets:", quality + "sets:"))
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history")
    _clear_error(done, "hostile.hevval.yaml", "data_quality.rate_limits.w", "never be checked")


# -- globbing only where a spec asks for it ----------------------------------------------------


def test_a_reference_path_naming_an_existing_file_is_that_file(project: Path) -> None:
    """``trip[1].csv`` exists beside ``trip1.csv`` (other data): the named file is scored."""
    (project / "ref.csv").rename(project / "trip[1].csv")
    t = np.arange(0.0, 30.0, 0.1)
    pd.DataFrame({"t": t, "v": np.cos(t) * 5}).to_csv(project / "trip1.csv", index=False)
    _spec(project, SPEC.replace("{path: ref.csv}", '{path: "trip[1].csv"}'))
    done = hevval(project, "run", "hostile.hevval.yaml", "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stderr
    (signal,) = json.loads((project / "out.json").read_text("utf-8"))["signals"]
    assert signal["mae"] == pytest.approx(0.01, abs=1e-9)


def test_a_campaign_in_a_folder_whose_name_looks_like_a_pattern(tmp_path: Path) -> None:
    folder = tmp_path / "camp[abc]"
    for side in ("ref", "sim"):
        (folder / side).mkdir(parents=True)
    t = np.arange(0.0, 30.0, 0.1)
    for trip in ("A", "B"):
        frame = pd.DataFrame({"t": t, "v": np.sin(t)})
        frame.to_csv(folder / "ref" / f"{trip}.csv", index=False)
        frame.assign(v=frame.v + 0.01).to_csv(folder / "sim" / f"{trip}.csv", index=False)
    spec = (
        "name: campaign\nreference: {path: ref/*.csv}\n"
        "model: {path: 'sim/{id}.csv'}\nsets:\n  - {signal: v}\n"
    )
    _spec(folder, spec)
    done = hevval(folder, "run", "hostile.hevval.yaml", "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stdout + done.stderr
    specs = json.loads((folder / "out.json").read_text("utf-8"))["specs"]
    assert len(specs) == 2


# -- signals and cleanup on every write --------------------------------------------------------

SLOW_REPORT = """\
import os
import sys
import time

from pytest_hevval import cli

fsync = os.fsync


def slow_fsync(fd):
    if os.readlink(f"/proc/self/fd/{fd}").endswith(".part") and "report" in os.readlink(
        f"/proc/self/fd/{fd}"
    ):
        print("writing", flush=True)
        time.sleep(60)
    fsync(fd)


os.fsync = slow_fsync
sys.exit(cli.main(sys.argv[1:]))
"""


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc to see the file")
def test_sigterm_while_a_report_is_written_leaves_no_temporary_file(project: Path) -> None:
    import signal
    import subprocess
    import sys

    (project / "slow.py").write_text(SLOW_REPORT, encoding="utf-8")
    argv = ["run", "hostile.hevval.yaml", "--no-history", "--report", "html,json,md"]
    with subprocess.Popen(
        [sys.executable, "slow.py", *argv], cwd=project, stdout=subprocess.PIPE, text=True
    ) as child:
        try:
            assert child.stdout is not None
            lines = iter(child.stdout.readline, "")
            assert "writing\n" in lines, "the report was never written"
            assert list((project / ".hevval" / "report").glob(".tmp-*.part"))
            child.send_signal(signal.SIGTERM)
            assert child.wait(timeout=30) == -signal.SIGTERM
        finally:
            child.kill()
    assert list((project / ".hevval" / "report").glob(".tmp-*")) == []


# -- specs pytest's walk would pass by --------------------------------------------------------


def test_pytest_names_a_spec_that_is_a_link_loop_or_dangling(pytester: pytest.Pytester) -> None:
    t = np.arange(0.0, 30.0, 0.1)
    pd.DataFrame({"t": t, "v": np.sin(t)}).to_csv(pytester.path / "ref.csv", index=False)
    pd.DataFrame({"t": t, "v": np.sin(t)}).to_csv(pytester.path / "sim.csv", index=False)
    _spec(pytester.path, SPEC)
    (pytester.path / "loop.hevval.yaml").symlink_to("loop.hevval.yaml")
    (pytester.path / "dangling.hevval.yaml").symlink_to("gone.hevval.yaml")
    result = pytester.runpytest_subprocess("--hevval", "-p", "no:cacheprovider")
    output = result.stdout.str()
    assert result.ret == pytest.ExitCode.INTERRUPTED, output
    assert "loop.hevval.yaml: cannot read the spec file (a loop of symbolic links)" in output
    assert (
        "dangling.hevval.yaml: cannot read the spec file (a symbolic link to "
        "'gone.hevval.yaml', which does not exist)" in output
    ), output
    result.assert_outcomes(errors=2)


# -- a model callable gets what it declares, and never a scored signal unasked ------------------

COPYCAT = '''\
import pandas as pd


def copy(frame):
    """A wrong model that reads the measured signal it is scored on."""
    return pd.DataFrame({"time": frame["time"], "v": frame["v"], "w": frame.get("w", 0.0)})
'''


def _copycat(project: Path, model_keys: str) -> str:
    t = np.arange(0.0, 30.0, 0.1)
    pd.DataFrame({"t": t, "v": np.sin(t), "w": np.cos(t)}).to_csv(project / "ref.csv", index=False)
    return _callable_spec(
        project, "copy", model_keys, source=COPYCAT, more="candidates: {heat: w}\n"
    )


def test_a_model_given_no_inputs_does_not_receive_the_signal_it_is_scored_on(
    project: Path,
) -> None:
    spec = _copycat(project, "")
    done = hevval(project, "run", spec, "--no-history")
    _clear_error(done, "model.inputs", "asked for the column 'v'", "scores", "driven_by:")


def test_a_scored_signal_among_the_inputs_is_refused_with_the_key_that_allows_it(
    project: Path,
) -> None:
    spec = _copycat(project, ", inputs: [v]")
    done = hevval(project, "run", spec, "--no-history")
    _clear_error(done, "model.inputs[0]", "a measured signal the spec scores", "driven_by:")


def test_a_model_driven_by_a_scored_signal_on_purpose(project: Path) -> None:
    spec = _copycat(project, ", driven_by: [v]")
    done = hevval(project, "run", spec, "--no-history", "--json", "out.json")
    assert done.returncode == 0, done.stderr
    (signal,) = json.loads((project / "out.json").read_text("utf-8"))["signals"]
    assert signal["mae"] == 0.0


def test_a_link_in_place_of_an_output_does_not_carry_the_write_elsewhere(project: Path) -> None:
    """The link is replaced by the new file; the file it pointed at is left as it was."""
    outside = project / "outside.txt"
    outside.write_text("keep", encoding="utf-8")
    report = project / ".hevval" / "report"
    report.mkdir(parents=True)
    for name in ("report.html", "report.json", "report.md"):
        (report / name).symlink_to(outside)
    (project / "out.json").symlink_to(outside)
    argv = ("run", "hostile.hevval.yaml", "--no-history", "--report", "html,json,md")
    done = hevval(project, *argv, "--json", "out.json")
    assert done.returncode == 0, done.stderr
    assert outside.read_text("utf-8") == "keep"
    for path in (report / "report.html", report / "report.json", project / "out.json"):
        assert not path.is_symlink(), path
        assert path.stat().st_size > 0


HELD_FOLDER = """\
import time

from pytest_hevval import files

files.remove_temporaries_on_signals()
with files.temporary_folder() as folder:
    (folder / "download.parquet").write_bytes(b"x" * 1000)
    print(folder, flush=True)
    time.sleep(60)
"""


def test_sigterm_removes_a_download_folder_in_flight(tmp_path: Path) -> None:
    """Data read from a URL is copied into a temporary folder first."""
    import signal
    import subprocess
    import sys

    with subprocess.Popen(
        [sys.executable, "-c", HELD_FOLDER], cwd=tmp_path, stdout=subprocess.PIPE, text=True
    ) as child:
        try:
            assert child.stdout is not None
            folder = Path(child.stdout.readline().strip())
            assert (folder / "download.parquet").is_file()
            child.send_signal(signal.SIGTERM)
            assert child.wait(timeout=30) == -signal.SIGTERM
        finally:
            child.kill()
    assert not folder.exists()

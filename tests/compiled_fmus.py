"""FMUs compiled from C here, for tests of the FMU runner on real binaries (not Python inside).

The C sources and model descriptions are the project's own (``tests/fmus/``); the FMI headers
come from the installed fmpy package. Each FMU is built once per test session into a temporary
folder. Without a C compiler or the headers the tests that need an FMU skip, except in CI,
where they fail: a CI machine has both.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest

from tests.conftest import IN_CI

SOURCES = Path(__file__).parent / "fmus"

#: FMI version → the header that declares every function, and the binaries' platform folder.
_HEADERS = {"2.0": "fmi2Functions.h", "3.0": "fmi3Functions.h"}
_DECLARED = re.compile(r"#define\s+(fmi[23]\w+)\s+fmi[23]FullName\(")
_DEFINED = re.compile(r"^[A-Za-z][\w\s\*]*?\b(fmi[23][A-Z]\w*)\(", re.MULTILINE)


def _unavailable(reason: str) -> None:
    if IN_CI:
        pytest.fail(f"{reason}; CI is set, so the compiled FMUs must be built: install gcc")
    pytest.skip(reason)


def _headers(fmi_version: str) -> Path:
    fmpy = pytest.importorskip("fmpy")
    folder = Path(fmpy.__file__).parent / "c-code"
    if not (folder / _HEADERS[fmi_version]).is_file():
        _unavailable(
            f"the installed fmpy ({fmpy.__version__}) ships no FMI {fmi_version} headers "
            f"in {folder}"
        )
    return folder


def build_fmu(name: str, fmi_version: str, out: Path) -> str:
    """Compile ``tests/fmus/<name>.c`` with its ``<name>.xml`` into ``out/<name>.fmu``.

    FMI functions the source does not define are added as stubs that return the FMI error
    status (3): fmpy looks every FMI function up when it loads the binary, and the tests call
    only some.
    """
    import fmpy

    compiler = shutil.which("gcc") or shutil.which("cc")
    if compiler is None:
        _unavailable("no C compiler (gcc or cc) on PATH")
    headers = _headers(fmi_version)
    source = SOURCES / f"{name}.c"
    declared = _DECLARED.findall((headers / _HEADERS[fmi_version]).read_text())
    defined = set(_DEFINED.findall(source.read_text()))
    stubs = out / f"{name}_stubs.c"
    stubs.write_text(
        "".join(f"int {f}(void) {{ return 3; }}\n" for f in declared if f not in defined)
    )
    # FMI 3 names the folder by a platform tuple (x86_64-linux), FMI 2 by a name (linux64).
    platform = fmpy.platform_tuple if fmi_version == "3.0" else fmpy.platform
    binary = f"binaries/{platform}/{name}{fmpy.sharedLibraryExtension}"
    library = out / binary
    library.parent.mkdir(parents=True, exist_ok=True)
    command = [compiler, "-shared", "-fPIC", "-O1", "-I", str(headers), str(source), str(stubs)]
    done = subprocess.run(
        [*command, "-o", str(library), "-lm"], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        pytest.fail(f"compiling {source} failed:\n{done.stderr}")
    fmu = out / f"{name}.fmu"
    with zipfile.ZipFile(fmu, "w") as archive:
        archive.write(SOURCES / f"{name}.xml", "modelDescription.xml")
        archive.write(library, binary)
    return os.fspath(fmu)

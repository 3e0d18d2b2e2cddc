# Sourced by .ci/min-versions and .ci/python-versions: an environment of its own for a test run,
# made in two parts, so that .ci/run can install it in the background while the README's
# command runs and test with it later.
#
# env_install DIR PYTHON [CONSTRAINTS]: a virtual environment in DIR/env with the dependencies
#   of ".[all,test]" (under CONSTRAINTS, a pip constraints file, when given); DIR/installed
#   marks it complete. pip builds the project from a copy of its sources in DIR/src
#   (pyproject.toml, README.md, the package): setuptools writes pytest_hevval.egg-info into the
#   tree it builds, and the README's `pip install -e .` may be building this tree meanwhile.
# env_ready DIR: installs the project from this tree into DIR/env (editable, without
#   dependencies: the environment is then the one `pip install -e ".[all,test]"` makes here)
#   and prints its versions. When DIR/installed is missing it prints the end of
#   DIR/install.log (where the scripts' `install DIR` form writes) and fails.
# env_test DIR [PYTEST_ARGS...]: env_ready, then runs the suite with it: -n 2, a fixed
#   Hypothesis seed, neither the browser test nor the emulated workflow (.ci/min-versions
#   says why).

env_install() {
    local dir="$1" python="$2" constraints="${3:-}"
    rm -rf "$dir/env" "$dir/src" "$dir/installed"
    mkdir -p "$dir/src"
    cp pyproject.toml README.md "$dir/src/"
    cp -r pytest_hevval "$dir/src/"
    find "$dir/src" -name __pycache__ -prune -exec rm -rf {} +
    "$python" -m venv "$dir/env"
    "$dir/env/bin/pip" install -q -U pip
    if [ -n "$constraints" ]; then
        "$dir/env/bin/pip" install -q -c "$constraints" -e "$dir/src[all,test]"
    else
        "$dir/env/bin/pip" install -q -e "$dir/src[all,test]"
    fi
    touch "$dir/installed"
}

env_ready() {
    local dir="$1"
    if [ ! -e "$dir/installed" ]; then
        echo "the environment in $dir was not installed; the end of its install log:"
        tail -n 80 "$dir/install.log" 2>/dev/null || echo "(no log: $dir/install.log)"
        return 1
    fi
    "$dir/env/bin/pip" install -q --no-deps -e .
    "$dir/env/bin/python" - <<'PY'
import platform, numpy, scipy, pandas, pytest
print(f"Python {platform.python_version()}, numpy {numpy.__version__}, "
      f"scipy {scipy.__version__}, pandas {pandas.__version__}, pytest {pytest.__version__}")
PY
}

env_test() {
    local dir="$1"
    shift
    env_ready "$dir" || return 1
    "$dir/env/bin/python" -m pytest -q -p no:cacheprovider -n 2 --hypothesis-seed=0 \
        -m "not browser and not deployment" "$@"
}

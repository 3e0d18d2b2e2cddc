#!/usr/bin/env bash
# Closing the loop on the example: score model v1, diagnose the residual where the error shows,
# score model v2 (which adds the effect found), diagnose it again, and compare the two runs.
# docs/closing-the-loop.md walks through what each step prints.
#
#   tools/loop.sh b03 | a12 | bus          the whole loop for one case
#   tools/loop.sh channels-only SPEC [hevval diagnose options...]
#                                          diagnose SPEC without its declared candidates, so
#                                          only the automatic channel candidates are tried
#   tools/loop.sh suspect SPEC NAME EXPR [hevval diagnose options...]
#                                          diagnose SPEC with NAME: EXPR as its only declared
#                                          candidate (the spec file is left as it is)
#
# Runs from example_project/ wherever it is called from. Results go to .hevval/loop/
# (HEVVAL_LOOP_DIR overrides); HEVVAL names the hevval command (default: hevval).
set -euo pipefail

cd "$(dirname "$0")/.."
hevval=${HEVVAL:-hevval}
out=${HEVVAL_LOOP_DIR:-.hevval/loop}
copy=""
trap 'rm -f "$copy"' EXIT

# A variant of a spec must sit next to it: the spec's relative data paths resolve from its
# folder. The leading dot and the .yaml suffix keep pytest and `hevval run specs` from
# collecting it (they look for *.hevval.yaml).
variant() {
    local spec=$1
    mktemp "$(dirname "$spec")/.$(basename "$spec" .hevval.yaml).variant.XXXXXX.yaml"
}

# The spec without its top-level `candidates:` block (up to the next top-level key).
strip_candidates() {
    awk '/^candidates:/ { skip = 1; next } skip && /^[^ #]/ { skip = 0 } !skip' "$1"
}

channels_only() {
    local spec=$1
    shift
    copy=$(variant "$spec")
    strip_candidates "$spec" >"$copy"
    "$hevval" diagnose "$copy" "$@"
}

suspect() {
    local spec=$1 name=$2 expression=$3
    shift 3
    copy=$(variant "$spec")
    {
        strip_candidates "$spec"
        # Single-quoted YAML keeps backticks and double quotes; a quote inside is doubled.
        printf "candidates:\n  %s: '%s'\n" "$name" "${expression//\'/\'\'}"
    } >"$copy"
    "$hevval" diagnose "$copy" "$@"
}

# `hevval run` exits 1 when a gate fails, which is the expected outcome for model v1.
score() {
    local spec=$1 json=$2
    "$hevval" run "$spec" --details --no-history --json "$json" || [ $? -eq 1 ]
}

step() {
    printf '\n$ %s\n' "$*"
}

loop() {
    local name=$1 before=$2 after=$3 signal=$4
    mkdir -p "$out"
    step hevval run "$before" --details --json "$out/$name-v1.json"
    score "$before" "$out/$name-v1.json"
    step hevval diagnose "$before" --signal "$signal"
    "$hevval" diagnose "$before" --signal "$signal" --json "$out/$name-v1-diagnosis.json"
    if grep -q '^candidates:' "$before"; then
        step hevval diagnose "$before" --signal "$signal" --no-channels
        "$hevval" diagnose "$before" --signal "$signal" --no-channels
        step tools/loop.sh channels-only "$before" --signal "$signal"
        channels_only "$before" --signal "$signal"
    fi
    step hevval run "$after" --details --json "$out/$name-v2.json"
    score "$after" "$out/$name-v2.json"
    # Diagnosing v2 the same way checks that the effect added is no longer in the residual.
    step hevval diagnose "$after" --signal "$signal"
    "$hevval" diagnose "$after" --signal "$signal" --json "$out/$name-v2-diagnosis.json"
    step hevval compare "$out/$name-v1.json" "$out/$name-v2.json"
    "$hevval" compare "$out/$name-v1.json" "$out/$name-v2.json"
}

case ${1:-} in
b03)
    loop b03 specs/i3-B03-winter-v1.hevval.yaml specs/i3-B03-winter-v2.hevval.yaml E_batt/P_batt
    ;;
a12)
    loop a12 specs/i3-A12-hills-v1.hevval.yaml specs/i3-A12-hills-v2.hevval.yaml E_batt/P_batt
    ;;
bus)
    loop bus specs/bus-mild-hybrid.hevval.yaml specs/bus-v2-accessory-load.hevval.yaml \
        FCcum/FCinst/Teng
    ;;
channels-only)
    [ $# -ge 2 ] || { echo "usage: tools/loop.sh channels-only SPEC [options]" >&2; exit 2; }
    shift
    channels_only "$@"
    ;;
suspect)
    [ $# -ge 4 ] || { echo "usage: tools/loop.sh suspect SPEC NAME EXPR [options]" >&2; exit 2; }
    shift
    suspect "$@"
    ;;
*)
    sed -n '2,15s/^# \{0,1\}//p' "$0" >&2
    exit 2
    ;;
esac

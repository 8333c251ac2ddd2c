#!/usr/bin/env bash
# Installs what the tests need (the package with its test extras, built from this checkout, into the
# project's virtual environment: see venv.sh) and runs the linters and every test in four tiers, timing each:
#   lint         rustfmt and clippy (warnings are errors) on the crates; ruff check and mypy on the Python
#                package and its stub (configured in rustfmt.toml, Cargo.toml and pyproject.toml)
#   rust         the Rust unit tests (cargo test, release optimisation without fat LTO)
#   python-fast  the Python suite without the tests marked slow (pytest -m "not slow": the inner loop)
#   python-slow  the tests marked slow (end-to-end experiments, simulations, browser rendering)
# Every tier runs even when an earlier one fails; the wall times are printed at the end, and the exit status
# is non-zero if any tier failed. LEGKIT_HYPOTHESIS_PROFILE selects the example counts (tests/conftest.py).
set -uo pipefail
cd "$(dirname "$0")/.."

declare -a names=() times=() results=()
status=0
tier() {  # tier NAME COMMAND...: run, time and record one step
    local name="$1" start rc
    shift
    echo "=== $name: $*"
    start=$EPOCHREALTIME
    "$@"
    rc=$?
    names+=("$name")
    times+=("$(awk -v a="$start" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f", b - a }')")
    results+=("$([[ $rc -eq 0 ]] && echo ok || echo "FAILED ($rc)")")
    [[ $rc -eq 0 ]] || status=1
    return "$rc"
}

setup() {
    source scripts/venv.sh &&
        python -m pip install --quiet ".[test]" &&
        # Headless Chromium renders the viewer's HTML in tests/test_viewer.py (Debian package; about 20 s to install).
        { command -v chromium >/dev/null ||
            { apt-get update -qq && apt-get install -y -qq --no-install-recommends chromium >/dev/null; }; }
}

lint() {  # every linter runs; the tier fails if any does
    local rc=0
    # A minimal rustup profile lacks them.
    { cargo fmt --version && cargo clippy --version; } >/dev/null 2>&1 || rustup component add rustfmt clippy || rc=1
    cargo fmt --all -- --check || rc=1
    cargo clippy --quiet --workspace --all-targets -- -D warnings || rc=1
    python -m ruff check || rc=1
    python -m mypy || rc=1
    return "$rc"
}

if tier setup setup; then
    tier lint lint
    # Optimised like the release build but without its fat LTO and single codegen unit, which make every
    # test binary slow to build; the wheel keeps them.
    tier rust env CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 \
        cargo test --release --workspace --exclude legkit-pybind
    tier python-fast python -m pytest tests -q -m "not slow"
    tier python-slow python -m pytest tests -q -m slow
fi

echo
echo "tier          wall time   result   (hypothesis profile: ${LEGKIT_HYPOTHESIS_PROFILE:-legkit})"
for i in "${!names[@]}"; do
    printf "%-12s %8s s   %s\n" "${names[$i]}" "${times[$i]}" "${results[$i]}"
done
exit "$status"

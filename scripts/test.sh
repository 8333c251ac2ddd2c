#!/usr/bin/env bash
# Installs what the tests need (the package with its test extras, built from this checkout, into the
# project's virtual environment: see venv.sh) and runs the linters and every test in five tiers, timing each:
#   lint         rustfmt and clippy (warnings are errors) on the crates; rustdoc on the core crate, with and
#                without its default features (every public item documented, no broken links: warnings are
#                errors); the core crate packaged (cargo package, offline, without its verifying build); ruff
#                check and mypy on the Python package and its stub (configured in rustfmt.toml,
#                Cargo.toml and pyproject.toml); the API reference built from the docstrings and the stub
#                (mkdocs.yml; warnings are errors)
#   rust         the Rust unit tests (cargo test, release optimisation without fat LTO: the profile the lint tier's
#                clippy and rustdoc use), and the core crate checked without its default features (no Rapier)
#   python-fast  the Python suite without the tests marked slow (pytest -m "not slow": the inner loop)
#   python-slow  the tests marked slow (end-to-end experiments, simulations), except the browser's
#                (both tiers on one pytest-xdist worker per core, -n auto: on 2 cores they take 0.55-0.6x their
#                serial wall time), then those marked serial alone (a worker's CPU after Ctrl-C, measured)
#   browser      the tests marked browser: the viewer's HTML rendered by headless Chromium. Chromium is
#                installed with apt-get as root, or through sudo when that needs no password; when it cannot
#                be, the tier is reported as NOT RUN in the summary (with the command that installs it)
# Runs as any user. Every tier runs even when an earlier one fails; the wall times are printed at the end, and
# the exit status is non-zero if any tier failed. LEGKIT_HYPOTHESIS_PROFILE selects the example counts
# (tests/conftest.py).
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

skip() {  # skip NAME REASON: record a tier that could not run
    names+=("$1")
    times+=("-")
    results+=("NOT RUN: $2")
}

setup() {
    source scripts/venv.sh &&
        legkit_install ".[test]" || return
    # Headless Chromium renders the viewer's HTML in tests/test_viewer.py (Debian package; about 20 s to
    # install). Without it the browser tier is reported as not run; the other tiers do not need it.
    command -v chromium >/dev/null ||
        { legkit_as_root apt-get update -qq && legkit_as_root apt-get install -y -qq --no-install-recommends chromium >/dev/null; } ||
        echo "chromium is not installed and cannot be without a password: the browser tier will not run" \
            "(install it with: sudo apt-get install chromium)"
    return 0
}

# clippy, rustdoc, the Rust tests and the feature check share one profile: the release profile without its fat LTO and
# single codegen unit, which make every test binary slow to build (the wheel keeps them). Sharing it, rustdoc and the
# check reuse clippy's checked dependencies, and the tests most of its build scripts and proc macros.
shared_profile_cargo() {  # shared_profile_cargo SUBCOMMAND ARGS...
    env CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 cargo "$1" --release "${@:2}"
}

lint() {  # every linter runs; the tier fails if any does
    local rc=0
    # A minimal rustup profile lacks them.
    { cargo fmt --version && cargo clippy --version; } >/dev/null 2>&1 || rustup component add rustfmt clippy || rc=1
    cargo fmt --all -- --check || rc=1
    shared_profile_cargo clippy --quiet --workspace --all-targets -- -D warnings || rc=1
    RUSTDOCFLAGS="-D warnings" shared_profile_cargo doc --quiet -p legkit-dynamics --no-deps || rc=1
    RUSTDOCFLAGS="-D warnings" shared_profile_cargo doc --quiet -p legkit-dynamics --no-deps --no-default-features || rc=1
    # The core as a crate (its manifest, the files it ships): packaged offline without the verifying build of the
    # tarball, which takes minutes (`cargo package -p legkit-dynamics` runs it).
    cargo package --quiet -p legkit-dynamics --no-verify --offline --allow-dirty || rc=1
    python -m ruff check || rc=1
    python -m mypy || rc=1
    local site
    site="$(mktemp -d)"
    python -m mkdocs build --strict --quiet --site-dir "$site" || rc=1
    rm -rf "$site"
    return "$rc"
}

python_slow() {  # the slow tests on every core, then the serial ones alone
    local rc=0
    python -m pytest tests -q -m "slow and not browser and not serial" -n auto || rc=1
    python -m pytest tests -q -m "serial and not browser" || rc=1
    return "$rc"
}

rust() {
    local rc=0
    shared_profile_cargo test --workspace --exclude legkit-pybind || rc=1
    shared_profile_cargo check --quiet -p legkit-dynamics --no-default-features || rc=1
    return "$rc"
}

if tier setup setup; then
    tier lint lint
    tier rust rust
    tier python-fast python -m pytest tests -q -m "not slow and not serial" -n auto
    tier python-slow python_slow
    if command -v chromium >/dev/null; then
        tier browser python -m pytest tests -q -m browser
    else
        skip browser "chromium missing (sudo apt-get install chromium)"
    fi
fi

echo
echo "tier          wall time   result   (hypothesis profile: ${LEGKIT_HYPOTHESIS_PROFILE:-legkit})"
for i in "${!names[@]}"; do
    printf "%-12s %8s s   %s\n" "${names[$i]}" "${times[$i]}" "${results[$i]}"
done
for result in "${results[@]}"; do
    [[ "$result" == "NOT RUN"* ]] && echo "Some tests did NOT run (see above): this run does not cover them."
done | sort -u
exit "$status"

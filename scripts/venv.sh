# Sourced by scripts/run.sh and scripts/test.sh: activates the project's Python environment, creating it when
# missing; returns non-zero if it cannot. An already active virtual environment ($VIRTUAL_ENV) is used as it
# is; otherwise .venv in this checkout (gitignored), made by `python3 -m venv` (or `$PYTHON -m venv`) and
# reused by later runs. A virtual environment is what `pip install` needs on a system Python marked
# externally managed (PEP 668: stock Debian and Ubuntu), where it refuses to install outside one. Debian and
# Ubuntu ship the venv module's pip bootstrap separately (python3.X-venv); it is installed with apt-get when
# missing, as root or through sudo when that needs no password; otherwise the command to run is printed.
# Also defines legkit_as_root and legkit_install.

legkit_as_root() {  # legkit_as_root COMMAND...: runs it as root (directly, or by sudo without a password prompt)
    if [[ "$(id -u)" -eq 0 ]]; then
        "$@"
    elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
        sudo -n "$@"
    else
        return 126
    fi
}

legkit_activate_venv() {
    [[ -n "${VIRTUAL_ENV:-}" ]] && return 0
    local python="${PYTHON:-python3}" version
    if ! .venv/bin/python -c "import sys" 2>/dev/null; then
        if ! "$python" -c "import ensurepip, venv" 2>/dev/null; then
            version="$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')" || return 1
            echo "installing python${version}-venv (the venv module's pip bootstrap for $python) with apt-get"
            if ! { legkit_as_root apt-get update -qq &&
                legkit_as_root apt-get install -y -qq --no-install-recommends "python${version}-venv" >/dev/null; }; then
                echo "cannot install python${version}-venv without a password; run this, then this script again:" >&2
                echo "  sudo apt-get install python${version}-venv" >&2
                return 1
            fi
        fi
        echo "creating the virtual environment .venv ($("$python" --version))"
        "$python" -m venv --clear .venv || return 1
        .venv/bin/python -m pip install --quiet --upgrade pip || return 1
    fi
    # shellcheck disable=SC1091
    source .venv/bin/activate
}

legkit_install() {  # legkit_install SPEC: pip-installs SPEC (".", ".[plot,viewer]", ...) from this checkout
    # A build compiles the Rust extension (cargo reuses target/ afterwards). The first takes minutes, so it
    # says so and shows cargo's progress (one line per crate compiled) instead of pip's silence.
    if python -c "import legkit" 2>/dev/null; then
        python -m pip install --quiet "$1"
        return
    fi
    echo "building legkit from this checkout: the first build compiles the Rust extension and its dependencies"
    echo "(about 5-6 minutes on 2 cores; later builds take seconds). Progress:"
    local log pid rc=0
    log="$(mktemp)"
    python -m pip install -v "$1" >"$log" 2>&1 &
    pid=$!
    # Follows the log until pip exits (callers may run under set -e and pipefail: no match is no error).
    tail -f --pid="$pid" "$log" | grep --line-buffered -E '^\s*(Compiling|Finished) ' | sed -u 's/^ */  /' || true
    wait "$pid" || rc=$?
    if [[ "$rc" -ne 0 ]]; then
        echo "pip install $1 failed; its last lines ($log has all):" >&2
        tail -n 30 "$log" >&2
    else
        rm -f "$log"
    fi
    return "$rc"
}

legkit_activate_venv

# Sourced by scripts/run.sh and scripts/test.sh: activates the project's Python environment, creating it when
# missing; returns non-zero if it cannot. An already active virtual environment ($VIRTUAL_ENV) is used as it
# is; otherwise .venv in this checkout (gitignored), made by `python3 -m venv` (or `$PYTHON -m venv`) and
# reused by later runs. A virtual environment is what `pip install` needs on a system Python marked
# externally managed (PEP 668: stock Debian and Ubuntu), where it refuses to install outside one. Debian and
# Ubuntu ship the venv module's pip bootstrap separately (python3.X-venv); it is installed with apt-get when
# missing.

legkit_activate_venv() {
    [[ -n "${VIRTUAL_ENV:-}" ]] && return 0
    local python="${PYTHON:-python3}" version sudo=""
    if ! .venv/bin/python -c "import sys" 2>/dev/null; then
        if ! "$python" -c "import ensurepip, venv" 2>/dev/null; then
            version="$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')" || return 1
            [[ "$(id -u)" -eq 0 ]] || sudo="sudo"
            echo "installing python${version}-venv (the venv module's pip bootstrap for $python) with apt-get"
            $sudo apt-get update -qq || return 1
            $sudo apt-get install -y -qq --no-install-recommends "python${version}-venv" >/dev/null || return 1
        fi
        echo "creating the virtual environment .venv ($("$python" --version))"
        "$python" -m venv --clear .venv || return 1
        .venv/bin/python -m pip install --quiet --upgrade pip || return 1
    fi
    # shellcheck disable=SC1091
    source .venv/bin/activate
}

legkit_activate_venv

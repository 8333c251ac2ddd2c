#!/usr/bin/env bash
# Installs what the tests need (the package with its test extras, built from this checkout) and runs every
# test: the Rust unit tests, then the Python suite. Exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --upgrade pip
python3 -m pip install --quiet ".[test]"
# Headless Chromium renders the viewer's HTML in tests/test_viewer.py (Debian package; about 20 s to install).
command -v chromium >/dev/null || { apt-get update -qq && apt-get install -y -qq --no-install-recommends chromium >/dev/null; }
cargo test --release --workspace --exclude legkit-pybind
python3 -m pytest tests -q

#!/usr/bin/env bash
# Installs what the tests need (the package with its test extras, built from this checkout) and runs every
# test: the Rust unit tests, then the Python suite. Exits non-zero on any failure.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip install --quiet --upgrade pip
python3 -m pip install --quiet ".[test]"
cargo test --release --workspace --exclude legkit-pybind
python3 -m pytest tests -q

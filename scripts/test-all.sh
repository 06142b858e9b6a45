#!/usr/bin/env bash
# Runs every check CI runs: formatting, lints, the Rust test suite, docs, and the Python
# interchange checks (in a venv it creates and fills from PyPI). Usage: scripts/test-all.sh
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

step "Python venv for interchange checks (.venv)"
req="usd-core OpenImageIO jsonschema pytest numpy"
if [ ! -x .venv/bin/python ] || [ "$(cat .venv/.voltab-req 2>/dev/null)" != "$req" ]; then
  rm -rf .venv
  python3 -m venv .venv
  .venv/bin/pip install --quiet --disable-pip-version-check $req
  echo "$req" > .venv/.voltab-req
fi

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (warnings are errors)"
cargo clippy --all-targets --locked -- -D warnings

step "cargo test"
cargo test --locked

step "main job end to end: the full default pipeline (release, opt-in test)"
cargo test --release --locked --test run_report -- --ignored

step "cargo doc (warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --locked --quiet

step "Python interchange checks"
VOLTAB_BIN="$(pwd)/target/debug/voltab" .venv/bin/python -m pytest -q tests/python

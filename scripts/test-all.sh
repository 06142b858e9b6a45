#!/usr/bin/env bash
# Runs every check CI runs: formatting, lints, the Rust test suite, docs, and the Python
# interchange checks (in a venv it creates and fills from PyPI), and the GPU path against the CPU on
# a software Vulkan adapter (lavapipe, installed from Debian's packages when missing), a sharded compile
# on a one-node Slurm cluster on localhost (slurm-wlm and munge from Debian's packages when missing),
# and a 60 s smoke run of every fuzz target (VOLTAB_FUZZ_SMOKE=0 skips it).
# Usage: scripts/test-all.sh        (VOLTAB_GPU=0 scripts/test-all.sh: without the GPU feature and tests,
#                                    for a machine that cannot install a Vulkan driver)
set -euo pipefail
cd "$(dirname "$0")/.."

# Each step names the free disk space too: a clean run fills ~9 GB (target 6.3, fuzz/target 2.0, .venv 0.6).
step() { printf '\n==> %s   [%s free on the build disk]\n' "$*" "$(df -h --output=avail . | tail -1 | tr -d ' ')"; }

features=()
if [ "${VOLTAB_GPU:-1}" != 0 ]; then
  features=(--features gpu)
  step "Vulkan software adapter for the GPU tests (Debian's mesa-vulkan-drivers: lavapipe)"
  if ! ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1; then
    as_root=()
    [ "$(id -u)" = 0 ] || as_root=(sudo)
    "${as_root[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${as_root[@]}" apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
  fi
  ls /usr/share/vulkan/icd.d/lvp_icd*.json
  # wgpu's Vulkan loader warns without a private runtime folder.
  export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
  chmod 700 "$XDG_RUNTIME_DIR"
fi

step "libLLVM >= 16 for Mitsuba's fast llvm_ad_rgb variant (Debian's libllvm19; the harness falls back to scalar_rgb without it)"
if ! ls /usr/lib/*-linux-gnu/libLLVM-19.so* /usr/lib/*-linux-gnu/libLLVM.so.19* >/dev/null 2>&1; then
  as_root=()
  [ "$(id -u)" = 0 ] || as_root=(sudo)
  { "${as_root[@]}" apt-get update -qq && DEBIAN_FRONTEND=noninteractive "${as_root[@]}" apt-get install -y -qq libllvm19 >/dev/null; } ||
    echo "libllvm19 not installed: the Mitsuba tests run on the (slower) scalar_rgb variant"
fi

step "Python venv for interchange checks and the Mitsuba reference (.venv)"
req="usd-core OpenImageIO jsonschema pytest numpy mitsuba"
if [ ! -x .venv/bin/python ] || [ "$(cat .venv/.voltab-req 2>/dev/null)" != "$req" ]; then
  rm -rf .venv
  python3 -m venv .venv
  .venv/bin/pip install --quiet --disable-pip-version-check $req
  echo "$req" > .venv/.voltab-req
fi

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (warnings are errors), with and without the gpu feature"
cargo clippy --all-targets --locked "${features[@]}" -- -D warnings
cargo clippy --lib --bins --locked -- -D warnings

step "cargo test ${features[*]}"
cargo test --locked "${features[@]}"

step "main job end to end: the full default pipeline (release, opt-in test)"
cargo test --release --locked --test run_report -- --ignored

step "cargo doc (warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --locked --quiet "${features[@]}"

step "Python interchange checks"
# test_validate.py runs `voltab validate --quality quick` with the release binary the run_report step built.
VOLTAB_BIN="$(pwd)/target/debug/voltab" VOLTAB_RELEASE_BIN="$(pwd)/target/release/voltab" \
  .venv/bin/python -m pytest -q tests/python

step "Slurm: a sharded compile on a one-node cluster on localhost, byte-identical to a local one (issue 38)"
# Installs slurm-wlm and munge when missing, starts and stops its own daemons (scripts/slurm-local.sh).
VOLTAB_BIN="$(pwd)/target/release/voltab" scripts/slurm-test.sh

# Fuzz smoke run (issue 37): every target for 60 s (VOLTAB_FUZZ_SMOKE=<seconds>; 0 skips it). Its
# instrumented release build of every dependency takes ~10 min on 2 cores the first time.
# libFuzzer itself is C++ (built by libfuzzer-sys): a C++ compiler is installed when missing.
if [ "${VOLTAB_FUZZ_SMOKE:-60}" != 0 ]; then
  step "fuzz smoke run (${VOLTAB_FUZZ_SMOKE:-60} s per target)"
  if ! command -v c++ >/dev/null; then
    as_root=()
    [ "$(id -u)" = 0 ] || as_root=(sudo)
    "${as_root[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${as_root[@]}" apt-get install -y -qq g++ >/dev/null
  fi
  fuzz/run.sh all "${VOLTAB_FUZZ_SMOKE:-60}" -seed=37  # a fixed seed: the same mutations on every machine
fi

#!/usr/bin/env bash
# Builds one fuzz target with libFuzzer's coverage instrumentation on the stable toolchain (the
# flags `cargo fuzz --sanitizer none` uses, so no extra tool is needed) and runs it.
#
#   fuzz/run.sh <target> [seconds=60] [extra libFuzzer flags…]
#   fuzz/run.sh all [seconds=60]          every target in turn (the CI smoke run)
#
# Targets: pipeline, vtab, table_lookup, gltf, usd. Seeds are made from the golden tables, the
# bundled pipelines and scenes (fuzz/seeds/<target>, rebuilt each run); the growing corpus is
# fuzz/corpus/<target> and crashes land in fuzz/artifacts/<target>/ (both git-ignored). Each
# crash becomes a regression test in tests/hardening.rs. Limits per input: 10 s, 4 GiB RSS.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here"
target=${1:?usage: fuzz/run.sh <target|all> [seconds] [libFuzzer flags...]}
secs=${2:-60}
shift $(( $# >= 2 ? 2 : 1 ))
triple=$(rustc -vV | sed -n 's/^host: //p')
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$here/target}

if [ "$target" = all ]; then
  for t in pipeline vtab table_lookup gltf usd; do "$here/run.sh" "$t" "$secs" "$@"; done
  exit 0
fi

seeds=seeds/$target
rm -rf "$seeds"
mkdir -p "$seeds" "corpus/$target" "artifacts/$target" mem
rm -f "mem/$target.txt"
case $target in
  pipeline) cp ../pipelines/*.ron ../tables/golden/golden.ron "$seeds"/ ;;
  vtab) cp ../tables/golden/*.vtab "$seeds"/ ;;
  table_lookup)
    { printf '\000'; cat ../tables/golden/golden_zh.vtab; } > "$seeds/zh.bin"
    { printf '\001'; cat ../tables/golden/golden_lobes.vtab; } > "$seeds/lobes.bin" ;;
  gltf) python3 make_glb_seeds.py ../scenes "$seeds" ;;
  usd) cp ../scenes/*.usda "$seeds"/ ;;
  *) echo "unknown target $target" >&2; exit 2 ;;
esac

RUSTFLAGS="${RUSTFLAGS:-} --cfg fuzzing -Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
  -Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
  -Cllvm-args=-sanitizer-coverage-trace-compares -Cdebug-assertions -Coverflow-checks" \
  cargo build --release --locked --target "$triple" --bin "$target"

# openusd's own hangs (e.g. a relationship path missing its '>') are contained in voltab by the
# guarded child process, not in the library: for the usd target, keep fuzzing past timeouts (each is
# still saved under artifacts/usd/ for triage) instead of stopping at the first. A stack overflow
# kills a child with no artifact (libFuzzer's C main skips Rust's overflow handler); the input is
# then left in the target's temporary folder, /tmp/.tmp*/fuzz.usd*.
extra=()
if [ "$target" = usd ]; then extra=(-fork=1 -ignore_timeouts=1 -ignore_ooms=1); fi

bin=$CARGO_TARGET_DIR/$triple/release/$target
"$bin" "${extra[@]}" -max_total_time="$secs" -timeout=10 -rss_limit_mb=4096 -max_len=1048576 -print_final_stats=1 \
  -artifact_prefix="artifacts/$target/" "$@" "corpus/$target" "$seeds"

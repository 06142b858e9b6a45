#!/usr/bin/env bash
# A sharded compile and bake on a real Slurm (issue 38): brings up a one-node cluster on localhost
# (scripts/slurm-local.sh: Debian's slurm-wlm and munge, installed when missing), submits
# `voltab slurm … --shards 4 --submit` for a small pipeline holding one table of each kind and one
# lightmap bake, SIGKILLs one compile task mid-way, resubmits (only the killed shard reruns; the stuck
# merge, bake array and bake merge are cancelled and replaced), waits for the bake merge job and checks
# every merged table, lightmap and probe file is byte-identical to a local `voltab run`.
# Stops the daemons it started (by pid) and removes its scratch folder. Takes about a minute.
# Usage: scripts/slurm-test.sh          (VOLTAB_BIN=path/to/voltab to test another build)
set -euo pipefail
cd "$(dirname "$0")/.."

say() { printf '[slurm-test %s] %s\n' "$(date +%T)" "$*"; }
fail() { say "FAILED: $*"; exit 1; }

voltab=${VOLTAB_BIN:-target/release/voltab}
if [ -z "${VOLTAB_BIN:-}" ]; then
  cargo build --release --locked --quiet
fi
voltab=$(realpath "$voltab")
pipeline=$(realpath tests/fixtures/shard/slurm.ron)

work=$(mktemp -d /tmp/voltab-slurm.XXXXXX)
state=$work/cluster
out=$work/farm
cleanup() {
  scripts/slurm-local.sh stop "$state" >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
eval "$(scripts/slurm-local.sh start "$state")"
export SLURM_CONF

say "local run (the bytes every merge must reproduce)"
"$voltab" run "$pipeline" --out "$work/local" >/dev/null

# Waits until job $1 has left the queue (bounded).
wait_gone() {
  for _ in $(seq 1 600); do
    [ -z "$(squeue -h -j "$1" -o %i 2>/dev/null)" ] && return 0
    sleep 0.5
  done
  fail "job $1 still queued after 300 s"
}

say "submit 4 shards + merge, 4 bake shards + merge"
first=$("$voltab" slurm "$pipeline" --shards 4 --out "$out" --submit)
echo "$first"
array=$(sed -n 's/^submitted array job \([0-9]*\).*/\1/p' <<<"$first")
merge1=$(sed -n 's/^submitted merge job \([0-9]*\).*/\1/p' <<<"$first")
[ -n "$array" ] && [ -n "$merge1" ] || fail "no job ids in: $first"

# SIGKILL the first array task seen running for a moment (its shard folder then has no manifest).
killed=""
for _ in $(seq 1 400); do
  running=$(squeue -h -j "$array" -t RUNNING -o %i 2>/dev/null | head -1)
  if [ -n "$running" ]; then
    sleep 0.5
    if squeue -h -j "$running" -t RUNNING -o %i 2>/dev/null | grep -q .; then
      scancel --signal=KILL "$running"
      killed=$running
      break
    fi
  fi
  sleep 0.1
done
[ -n "$killed" ] || fail "no array task was seen running long enough to kill"
say "killed task $killed"
wait_gone "$array"
task=${killed#*_}
[ ! -f "$out/shards/compile-$task/shard.json" ] || fail "the killed shard $task has a manifest"
state_of_merge=$(squeue -h -j "$merge1" -o '%T %r' 2>/dev/null || true)
say "merge job $merge1 after the kill: ${state_of_merge:-gone}"
[ ! -f "$out/shard_lobes.vtab" ] || fail "a table was published although a shard failed"

say "resubmit: only the missing shard"
second=$("$voltab" slurm "$pipeline" --shards 4 --out "$out" --submit)
echo "$second"
grep -q "1 of 4 shards pending: \[$task\]" <<<"$second" || fail "expected only shard $task to be resubmitted"
merge2=$(sed -n 's/^submitted merge job \([0-9]*\).*/\1/p' <<<"$second")
bake2=$(sed -n 's/^submitted bake merge job \([0-9]*\).*/\1/p' <<<"$second")
[ -n "$merge2" ] && [ -n "$bake2" ] || fail "no merge or bake merge job in: $second"
grep -q "4 of 4 bake shards pending" <<<"$second" || fail "expected all 4 bake shards to be submitted"
grep -q "cancelled the pending job" <<<"$second" || fail "expected the stuck jobs of the first submission to be cancelled"
wait_gone "$merge2"
wait_gone "$bake2"
cat "$out/slurm/logs/compile-$task.log"
cat "$out/slurm/logs/merge.log"
cat "$out/slurm/logs/bake-0.log"
cat "$out/slurm/logs/merge-bake.log"

say "byte identity with the local compile"
n=0
for f in "$work/local"/*.vtab; do
  cmp "$f" "$out/$(basename "$f")" || fail "$(basename "$f") differs from the local compile"
  n=$((n + 1))
done
[ "$n" -eq 4 ] || fail "expected 4 tables, compared $n"
m=0
for f in "$work/local"/farm_bake/*.exr "$work/local"/farm_bake/*.png "$work/local"/farm_bake/probes.vtab; do
  cmp "$f" "$out/farm_bake/$(basename "$f")" || fail "farm_bake/$(basename "$f") differs from the local run"
  m=$((m + 1))
done
[ "$m" -eq 7 ] || fail "expected 3 lightmaps as EXR and PNG and the probes, compared $m"
say "PASSED: $n tables and $m bake outputs byte-identical after a killed task and a resubmission"

#!/usr/bin/env bash
# tests/fuzz/fuzz.sh: run or replay the libFuzzer harnesses (docs/reliability.md).
#   fuzz.sh run    <fuzz-bin-dir> <harness|all> <seconds>   fuzz; new inputs go to the work dir
#   fuzz.sh replay <fuzz-bin-dir> <harness|all>             each corpus file and reproducer once
# Limits per input (the resource budget plus headroom for ASan): 5 s, 1 GB RSS and malloc.
# Environment: FUZZ_JOBS=N runs N harnesses at a time in `run` mode (default 1);
# CLOTHFIT_FUZZ_WORK=<dir> holds the per-harness work corpora and logs (<dir>/<harness>/
# last-run.log); FUZZ_LOG_DIR=<dir> also copies each run's log to <dir>/<harness>.log.
set -uo pipefail
MODE=$1
BIN_DIR=$(realpath "$2")
WHICH=$3
SECONDS_PER=${4:-60}
HERE=$(cd "$(dirname "$0")" && pwd)
HARNESSES=(scene_card gltf glb weave fabric preset weave_maps merl image_exr image_png image_hdr
           convert_json convert_gltf convert_glb)
FLAGS=(-rss_limit_mb=1024 -malloc_limit_mb=1024 -timeout=5)
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=0:abort_on_error=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
TMPROOT=$(mktemp -d "${TMPDIR:-/tmp}/clothfit-fuzz.XXXXXX")
trap 'rm -rf "$TMPROOT"' EXIT
export CLOTHFIT_FUZZ_TMP=$TMPROOT
tar xzf "$HERE/regressions/fuzz-crashers.tar.gz" -C "$TMPROOT"
cp -r "$HERE/regressions/extra/." "$TMPROOT/"

regressions_of() {
  awk -v h="$1" '$1 == h { print $2 }' "$HERE/regressions/harnesses.txt" |
    while read -r rel; do echo "$TMPROOT/$rel"; done
}
max_len_of() {
  case "$1" in glb|image_*|convert_glb) echo 2097152 ;; *) echo 262144 ;; esac
}

[ "$WHICH" = all ] && list=("${HARNESSES[@]}") || read -r -a list <<<"${WHICH//,/ }"
for h in "${list[@]}"; do
  [ -x "$BIN_DIR/fuzz_$h" ] || { echo "fuzz.sh: missing $BIN_DIR/fuzz_$h (configure with -DCLOTHFIT_FUZZ=ON)"; exit 1; }
done

replay_one() {
  local h=$1 exe="$BIN_DIR/fuzz_$1" log="$TMPROOT/$1.log" start files
  mapfile -t files < <(find "$HERE/corpus/$h" -type f | sort; regressions_of "$h")
  start=$(date +%s.%N)
  if "$exe" "${FLAGS[@]}" "${files[@]}" >"$log" 2>&1; then
    printf 'fuzz.replay %s: %d inputs ok (%.1f s)\n' "$h" "${#files[@]}" "$(echo "$(date +%s.%N) - $start" | bc)"
  else
    echo "fuzz.replay $h: FAILED"; tail -n 40 "$log"; return 1
  fi
}

# One harness for SECONDS_PER seconds. Prints one summary line: seconds (wall), executions
# (libFuzzer's stat::number_of_executed_units), corpus (units in the work dir after the run,
# and libFuzzer's final corp: figure), and whether anything was found.
run_one() {
  local h=$1 exe="$BIN_DIR/fuzz_$1" work log rc start secs execs corp units dict=()
  case "$h" in scene_card|preset|fabric|convert_json|gltf|convert_gltf) dict=(-dict="$HERE/json.dict") ;; esac
  work="${CLOTHFIT_FUZZ_WORK:-$HERE/../../build-san/fuzz-work}/$h"
  mkdir -p "$work/corpus"
  log="$work/last-run.log"
  start=$(date +%s)
  "$exe" "${FLAGS[@]}" "${dict[@]}" -max_len="$(max_len_of "$h")" -max_total_time="$SECONDS_PER" \
    -print_final_stats=1 -artifact_prefix="$work/" "$work/corpus" "$HERE/corpus/$h" >"$log" 2>&1
  rc=$?
  secs=$(( $(date +%s) - start ))
  [ -n "${FUZZ_LOG_DIR:-}" ] && { mkdir -p "$FUZZ_LOG_DIR"; cp "$log" "$FUZZ_LOG_DIR/$h.log"; }
  execs=$(grep -Eo 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -Eo '[0-9]+$' | tail -n1)
  [ -n "$execs" ] || execs=$(grep -Eo '^#[0-9]+' "$log" | tail -n1 | tr -d '#')
  corp=$(grep -Eo 'corp: [0-9]+/[0-9]+[a-zA-Z]*' "$log" | tail -n1 | sed 's/corp: //')
  units=$(find "$work/corpus" -type f | wc -l)
  if [ $rc -eq 0 ]; then
    echo "fuzz $h: ${secs} s, ${execs:-?} executions, corpus ${corp:-?} (work dir $units files), nothing found"
  else
    echo "fuzz $h: FOUND something after ${execs:-?} executions, ${secs} s (rc $rc); artifacts in $work"
    grep -E 'ERROR|SUMMARY|fuzz oracle|runtime error|Test unit written' "$log" | head -n 8
    return 1
  fi
}

status=0
if [ "$MODE" = replay ]; then
  for h in "${list[@]}"; do replay_one "$h" || status=1; done
else
  JOBS=${FUZZ_JOBS:-1}
  running=0
  for h in "${list[@]}"; do
    if [ "$running" -ge "$JOBS" ]; then wait -n || status=1; running=$((running - 1)); fi
    run_one "$h" &
    running=$((running + 1))
  done
  while [ "$running" -gt 0 ]; do wait -n || status=1; running=$((running - 1)); done
fi
exit $status

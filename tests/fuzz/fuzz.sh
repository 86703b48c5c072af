#!/usr/bin/env bash
# tests/fuzz/fuzz.sh: run or replay the libFuzzer harnesses (docs/reliability.md).
#   fuzz.sh run    <fuzz-bin-dir> <harness|all> <seconds>   fuzz; new inputs go to the work dir
#   fuzz.sh replay <fuzz-bin-dir> <harness|all>             each corpus file and reproducer once
# Limits per input (the resource budget plus headroom for ASan): 5 s, 1 GB RSS and malloc.
set -uo pipefail
MODE=$1
BIN_DIR=$(realpath "$2")
WHICH=$3
SECONDS_PER=${4:-60}
HERE=$(cd "$(dirname "$0")" && pwd)
HARNESSES=(scene_card gltf glb weave fabric preset merl image_exr image_png image_hdr
           convert_json convert_gltf convert_glb)
FLAGS=(-rss_limit_mb=1024 -malloc_limit_mb=1024 -timeout=5)
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=0:abort_on_error=1:allocator_may_return_null=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-halt_on_error=1:print_stacktrace=1}
TMPROOT=$(mktemp -d "${TMPDIR:-/tmp}/clothfit-fuzz.XXXXXX")
trap 'rm -rf "$TMPROOT"' EXIT
export CLOTHFIT_FUZZ_TMP=$TMPROOT
tar xzf "$HERE/regressions/fuzz-crashers.tar.gz" -C "$TMPROOT"

regressions_of() {
  awk -v h="$1" '$1 == h { print $2 }' "$HERE/regressions/harnesses.txt" |
    while read -r rel; do echo "$TMPROOT/$rel"; done
}
max_len_of() {
  case "$1" in glb|image_*|convert_glb) echo 2097152 ;; *) echo 262144 ;; esac
}

[ "$WHICH" = all ] && list=("${HARNESSES[@]}") || list=("$WHICH")
status=0
for h in "${list[@]}"; do
  exe="$BIN_DIR/fuzz_$h"
  [ -x "$exe" ] || { echo "fuzz.sh: missing $exe (configure with -DCLOTHFIT_FUZZ=ON)"; exit 1; }
  dict=()
  case "$h" in scene_card|preset|fabric|convert_json|gltf|convert_gltf) dict=(-dict="$HERE/json.dict") ;; esac
  if [ "$MODE" = replay ]; then
    mapfile -t files < <(find "$HERE/corpus/$h" -type f | sort; regressions_of "$h")
    log="$TMPROOT/$h.log"
    start=$(date +%s)
    if "$exe" "${FLAGS[@]}" "${files[@]}" >"$log" 2>&1; then
      echo "fuzz.replay $h: ${#files[@]} inputs ok ($(( $(date +%s) - start )) s)"
    else
      echo "fuzz.replay $h: FAILED"; tail -n 40 "$log"; status=1
    fi
  else
    work="${CLOTHFIT_FUZZ_WORK:-$HERE/../../build-san/fuzz-work}/$h"
    mkdir -p "$work"
    log="$work/last-run.log"
    "$exe" "${FLAGS[@]}" "${dict[@]}" -max_len="$(max_len_of "$h")" -max_total_time="$SECONDS_PER" \
      -print_final_stats=1 -artifact_prefix="$work/" "$work" "$HERE/corpus/$h" >"$log" 2>&1
    rc=$?
    execs=$(grep -Eo 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -Eo '[0-9]+$' || echo '?')
    cov=$(grep -Eo 'cov: [0-9]+' "$log" | tail -n1 | grep -Eo '[0-9]+' || echo '?')
    if [ $rc -eq 0 ]; then
      echo "fuzz $h: ${SECONDS_PER} s, $execs executions, cov $cov, nothing found"
    else
      echo "fuzz $h: FOUND something after $execs executions (rc $rc); artifacts in $work"
      grep -E 'ERROR|SUMMARY|fuzz oracle|runtime error' "$log" | head -n 8
      status=1
    fi
  fi
done
exit $status

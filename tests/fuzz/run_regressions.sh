#!/usr/bin/env bash
# Replays the reproducers of issue 14 through the clothfit executable (ctest cli.regressions,
# in the Release and the sanitize builds). For each line of regressions/cases.txt: exit code in
# the allowed set (never a signal), the message names the file, under 5 s of CPU time and 1 GB
# (a wall-clock kill at CLOTHFIT_REGRESSION_TIMEOUT, default 60 s, catches hangs; CPU time is
# what is checked, so a loaded machine does not fail the test).
# usage: run_regressions.sh <clothfit> [case-filter-regex]
set -uo pipefail
BIN=$(realpath "$1")
FILTER=${2:-.}
HERE=$(cd "$(dirname "$0")" && pwd)
DATASETS=$(cd "$HERE/../../datasets" && pwd)
TMP=$(mktemp -d "${TMPDIR:-/tmp}/clothfit-regressions.XXXXXX")
trap 'rm -rf "$TMP"' EXIT
tar xzf "$HERE/regressions/fuzz-crashers.tar.gz" -C "$TMP"
# Reproducers found later by the harnesses (one folder each) sit next to the tarball's.
cp -r "$HERE/regressions/extra/." "$TMP/"
TIMEOUT_S=${CLOTHFIT_REGRESSION_TIMEOUT:-60}
MAX_CPU_S=5
MAX_KB=1048576
fails=0
n=0
while IFS= read -r line; do
  case "$line" in ''|'#'*) continue ;; esac
  [[ "$line" =~ $FILTER ]] || continue
  read -r folder rcs mention extra <<<"${line%% -- *}"
  args=${line#* -- }
  args=${args//@DATASETS@/$DATASETS}
  args=${args//@REPRO@/$TMP}
  n=$((n + 1))
  work="$TMP/run$n"
  cp -r "$TMP/$folder" "$work"
  mkdir -p "$work/OUT"
  start=$(date +%s.%N)
  # shellcheck disable=SC2086
  (cd "$work" && /usr/bin/time -f '%M %U %S' -o "$work/.rss" timeout -s KILL "$TIMEOUT_S" \
      "$BIN" --quiet $args >"$work/.stdout" 2>"$work/.stderr")
  rc=$?
  secs=$(echo "$(date +%s.%N) - $start" | bc)
  read -r rss ucpu scpu < <(tail -n1 "$work/.rss" 2>/dev/null | grep -E '^[0-9]+ ' || echo "0 0 0")
  cpu=$(echo "$ucpu + $scpu" | bc)
  msg=$(cat "$work/.stderr" "$work/OUT/convert-log.json" 2>/dev/null)
  status=ok
  if ! [[ ",$rcs," == *",$rc,"* ]]; then status="exit $rc, expected $rcs"; fi
  if [ "$status" = ok ] && [[ "$msg" != *"$mention"* ]]; then status="message does not mention '$mention'"; fi
  if [ "$status" = ok ] && [ "${rss:-0}" -gt "$MAX_KB" ]; then status="max RSS ${rss} KB over 1 GB"; fi
  if [ "$status" = ok ] && [ "$(echo "$cpu > $MAX_CPU_S" | bc)" = 1 ]; then status="${cpu} s CPU, over ${MAX_CPU_S} s"; fi
  if [ "$status" = ok ] && [[ "$args" == convert* ]] && [ ! -f "$work/OUT/convert-log.json" ]; then
    status="no convert-log.json written"
  fi
  # Optional checks after the message: creates=<file>[,<file>...] (the rest of a batch was
  # converted), failed=<N> (convert-log.json counts exactly N failed items, each with a reason),
# logclean (no control byte or DEL in any reason of convert-log.json).
  for kv in $extra; do
    [ "$status" = ok ] || break
    case "$kv" in
      creates=*)
        IFS=, read -r -a want <<<"${kv#creates=}"
        for f in "${want[@]}"; do
          [ -s "$work/$f" ] || { status="$f not written (the rest of the batch did not complete)"; break; }
        done ;;
      failed=*)
        got=$(python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); f=[i for i in d["items"] if i["status"]=="failed" and i.get("reason")]; print(d["failed"] if d["failed"]==len(f) else -1)' "$work/OUT/convert-log.json" 2>/dev/null || echo "?")
        [ "$got" = "${kv#failed=}" ] || status="convert-log.json: $got failed items with a reason, expected ${kv#failed=}" ;;
      logclean)  # no control byte or DEL in any reason of convert-log.json (decoded)
        python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); bad=[i["file"] for i in d["items"] if any(ord(c)<32 or 127<=ord(c)<160 for c in i.get("reason",""))]; sys.exit(1 if bad else 0)' "$work/OUT/convert-log.json" 2>/dev/null ||
          status="convert-log.json: a reason carries control bytes" ;;
      *) status="cases.txt: unknown check '$kv'" ;;
    esac
  done
  printf '%-40s rc=%s wall %5.2fs cpu %5.2fs %8s KB  %s\n' "$folder" "$rc" "$secs" "$cpu" "$rss" "$status"
  if [ "$status" != ok ]; then
    fails=$((fails + 1))
    echo "    command: clothfit $args"
    head -c 600 "$work/.stderr" | sed 's/^/    stderr: /'
  fi
done <"$HERE/regressions/cases.txt"
echo "$n cases, $fails failed"
[ "$n" -gt 0 ] && [ "$fails" -eq 0 ]

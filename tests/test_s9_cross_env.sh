#!/usr/bin/env bash
# tests/test_s9_cross_env.sh SRC: scripts/cross-env's refit options (s9-xenv).
# Runs scripts/cross-env against a stub clothfit (a shell script that records its arguments and
# answers render-reference, evaluate --json and fit), so the script's plumbing is tested without
# rendering: CROSS_ENV_FIT_ARGS reaches the refits and only them, the refit table's ratios are
# computed from the stub's figures, and an in-sample mismatch between evaluate and the preset's
# fit.rmse stops the script with the preset named.
set -euo pipefail
SRC=${1:?usage: $0 SRC}
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

cat > "$T/clothfit" <<'STUB'
#!/usr/bin/env bash
echo "$*" >> "$STUB_LOG"
[ "$1" = --quiet ] && shift
cmd=$1; shift
out=""; preset=""; refs=""
while [ $# -gt 0 ]; do
  case $1 in
    --out) out=$2; shift ;;
    --preset) preset=$2; shift ;;
    --references) refs=$2; shift ;;
  esac
  shift
done
case $cmd in
  render-reference) : > "$out" ;;
  evaluate)
    if [ -z "$refs" ]; then
      python3 -c 'import json,sys; print(json.dumps({"rmse": json.load(open(sys.argv[1]))["fit"]["rmse"] + float(sys.argv[2])}))' "$preset" "${STUB_IN_OFFSET:-0}"
    else
      echo '{"rmse": 0.02}'
    fi ;;
  fit) echo '{"fit": {"rmse": 0.015}}' > "$out" ;;
  *) echo "stub: unexpected $cmd" >&2; exit 9 ;;
esac
STUB
chmod +x "$T/clothfit"
mkdir -p "$T/presets"
echo '{"fit": {"rmse": 0.01, "level": 4, "pixel_stride": 4, "space": "display"}}' > "$T/presets/canvas_woven.json"

run() {  # run DIR [FIT_ARGS]
  STUB_LOG="$T/$1.log" CLOTHFIT="$T/clothfit" CROSS_ENV_DIR="$T/$1" CROSS_ENV_REFIT=1 \
    CROSS_ENV_FABRICS=canvas CROSS_ENV_MODELS=woven CROSS_ENV_ENVS=blender-city \
    CROSS_ENV_FIT_ARGS="${2:-}" "$SRC/scripts/cross-env" "$T/presets" > "$T/$1.out" 2> "$T/$1.err"
}

# 1. CROSS_ENV_FIT_ARGS reaches the refit, not the renders or the evaluations.
export STUB_LOG
run fis "--woven-ibl fis --fis-taps 8" || fail "cross-env with CROSS_ENV_FIT_ARGS failed: $(cat "$T/fis.err")"
grep -q '^--quiet fit .*--out .*/blender-city/refit/canvas_woven.json --woven-ibl fis --fis-taps 8$' "$T/fis.log" \
  || fail "the refit did not get CROSS_ENV_FIT_ARGS: $(grep ' fit ' "$T/fis.log")"
[ "$(grep -c -- '--woven-ibl' "$T/fis.log")" = 1 ] || fail "CROSS_ENV_FIT_ARGS leaked into other commands"
[ "$(grep -c '^--quiet render-reference' "$T/fis.log")" = 3 ] || fail "expected 3 reference renders"
# in-sample 0.01000, out 0.02000 (ratio 2.00), refit 0.01500 (vs refit 1.33)
grep -q "$(printf '^canvas\twoven\t0.01000\t0.02000\t2.00\t0.01500\t1.33$')" "$T/fis/cross-env-refit.tsv" \
  || fail "unexpected refit table: $(cat "$T/fis/cross-env-refit.tsv")"

# 2. Without it the refit command carries no extra option.
run plain || fail "cross-env without CROSS_ENV_FIT_ARGS failed: $(cat "$T/plain.err")"
grep -q '^--quiet fit .*--out [^ ]*/canvas_woven.json$' "$T/plain.log" \
  || fail "unexpected refit command: $(grep ' fit ' "$T/plain.log")"

# 3. A cached refit is reused: a second run does not refit.
run fis "--woven-ibl fis --fis-taps 8" || fail "second run failed"
[ "$(grep -c '^--quiet fit ' "$T/fis.log")" = 1 ] || fail "the cached refit was redone"

# 4. evaluate disagreeing with the preset's fit.rmse in-sample stops the script, naming the preset.
if STUB_IN_OFFSET=0.001 run bad; then fail "an in-sample mismatch was accepted"; fi
grep -q 'canvas_woven.json: evaluate gives 0.01100 in-sample, the fit recorded 0.01000' "$T/bad.err" \
  || fail "unexpected error: $(cat "$T/bad.err")"
# 5. A preset with weave maps is refitted with its own map filter (weave_maps.anisotropy; a
#    preset with maps but no key: 1, the filter of presets before session 9).
echo '{"fit": {"rmse": 0.01, "level": 4, "pixel_stride": 4, "space": "display"}, "weave_maps": {"file": "m.exr", "anisotropy": 16}}' > "$T/presets/canvas_woven.json"
run maps16 || fail "run with maps failed: $(cat "$T/maps16.err")"
grep -q '^--quiet fit .*--map-anisotropy 16$' "$T/maps16.log" || fail "refit without the preset's anisotropy: $(grep ' fit ' "$T/maps16.log")"
echo '{"fit": {"rmse": 0.01, "level": 4, "pixel_stride": 4, "space": "display"}, "weave_maps": {"file": "m.exr"}}' > "$T/presets/canvas_woven.json"
run maps1 || fail "run with old maps failed: $(cat "$T/maps1.err")"
grep -q '^--quiet fit .*--map-anisotropy 1$' "$T/maps1.log" || fail "old preset refit not at anisotropy 1: $(grep ' fit ' "$T/maps1.log")"
echo "cross-env: 5 checks passed"

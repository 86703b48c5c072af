#!/usr/bin/env bash
# s8-fis-cpp: the command-line side of woven FIS and of the fits' IBL engine:
# test_s8_fis_cli.sh <clothfit> <source dir>. Bad --ibl-engine / --woven-ibl values and a bad
# preset "woven" IBL field fail with an error naming the option or field; no preset is written.
set -uo pipefail
BIN=$1
SRC=$2
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
SCENE="$SRC/datasets/scenes/sphere.json"

err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --ibl-engine vulkan \
      --out "$TMP/f.json" 2>&1) && fail "fit --ibl-engine vulkan accepted"
echo "$err" | grep -q -- "--ibl-engine" || fail "fit error does not name --ibl-engine: $err"
[ ! -e "$TMP/f.json" ] || fail "preset written despite a bad --ibl-engine"

err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
      --woven-ibl exact --out "$TMP/f.json" 2>&1) && fail "fit --woven-ibl exact accepted"
echo "$err" | grep -q -- "--woven-ibl" || fail "fit error does not name --woven-ibl: $err"

err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
      --fis-taps 0 --out "$TMP/f.json" 2>&1) && fail "fit --fis-taps 0 accepted"
echo "$err" | grep -q -- "--fis-taps" || fail "fit error does not name --fis-taps: $err"

# FIS exists on the three.js engine only: asking for it on Filament's is an error (before any
# reference is read).
err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
      --ibl-engine filament --woven-ibl fis --out "$TMP/f.json" 2>&1) \
  && fail "fit --woven-ibl fis --ibl-engine filament accepted"
echo "$err" | grep -q "three.js IBL engine" || fail "fis on filament: $err"
[ ! -e "$TMP/f.json" ] || fail "preset written despite an error"

err=$("$BIN" --quiet evaluate --preset "$TMP/none.json" --ibl-engine metal 2>&1) \
  && fail "evaluate --ibl-engine metal accepted"
echo "$err" | grep -q -- "--ibl-engine" || fail "evaluate error does not name --ibl-engine: $err"

printf '{"schema":"clothfit.preset","version":1,"model":"woven","parameters":{},"woven":{"ibl":"fis","fis_taps":100}}' > "$TMP/w.json"
err=$("$BIN" render-preview --scene "$SCENE" --material "$TMP/w.json" --out "$TMP/p.png" 2>&1) \
  && fail "fis_taps 100 accepted"
echo "$err" | grep -q "woven.fis_taps" || fail "error does not name woven.fis_taps: $err"
echo "$err" | grep -q "w.json" || fail "error does not name the file: $err"
printf '{"schema":"clothfit.preset","version":1,"model":"woven","parameters":{},"woven":{"ibl":"fast"}}' > "$TMP/w.json"
err=$("$BIN" render-preview --scene "$SCENE" --material "$TMP/w.json" --out "$TMP/p.png" 2>&1) \
  && fail "ibl fast accepted"
echo "$err" | grep -q "woven.ibl" || fail "error does not name woven.ibl: $err"
echo "PASS"

#!/usr/bin/env bash
# s9-vis: the command-line side of the preview's visibility prototype (docs/visibility.md):
# test_s9_visibility_cli.sh <clothfit> <source dir>. Bad --ao-weighting, --vis-samples,
# --vis-bounces and --indirect-albedo values fail (fit and evaluate) with an error naming the
# option; no preset is written. The unit tests are tests/test_s9_visibility.cpp (S9Visibility.*).
. "$(dirname "$0")/cli_common.sh"

check() {  # check <option named in the error> <args...>
  local name=$1; shift
  err=$("$BIN" --quiet "$@" 2>&1) && fail "$* accepted"
  echo "$err" | grep -q -- "$name" || fail "error of '$*' does not name $name: $err"
}
for cmd in fit evaluate; do
  if [ $cmd = fit ]; then base=(fit --references "$TMP/none.exr" --scenes "$SCENE" --out "$TMP/f.json")
  else base=(evaluate --preset "$TMP/none.json"); fi
  check --ao-weighting "${base[@]}" --ao --ao-weighting sky
  check --vis-samples "${base[@]}" --ao --vis-samples 0
  check --vis-bounces "${base[@]}" --indirect --vis-bounces 9
done
# --indirect-albedo is parsed when the options are built (after the inputs are read): give fit a
# reference that exists so that the albedo is what fails.
"$BIN" --quiet render-reference --scene "$SCENE" --fabric "$SRC/datasets/fabrics/canvas.json" \
  --spp 1 --out "$TMP/ref.exr" > /dev/null 2>&1 || fail "render-reference failed"
check --indirect-albedo fit --references "$TMP/ref.exr" --scenes "$SCENE" --indirect \
  --indirect-albedo 2,0,0 --out "$TMP/f.json"
check --indirect-albedo fit --references "$TMP/ref.exr" --scenes "$SCENE" --indirect \
  --indirect-albedo 0.5,0.5 --out "$TMP/f.json"
# Tuning flags without the term they tune are errors, not ignored (session 9 review).
check --vis-samples fit --references "$TMP/ref.exr" --scenes "$SCENE" --vis-samples 5 --out "$TMP/f.json"
check --vis-bounces fit --references "$TMP/ref.exr" --scenes "$SCENE" --ao --vis-bounces 2 --out "$TMP/f.json"
check --ao-weighting fit --references "$TMP/ref.exr" --scenes "$SCENE" --indirect \
  --ao-weighting environment --out "$TMP/f.json"
[ ! -e "$TMP/f.json" ] || fail "preset written despite a bad option"
echo "ok"

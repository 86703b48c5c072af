#!/usr/bin/env bash
# s9-vis: the command-line side of the preview's visibility prototype (docs/visibility.md):
# test_s9_visibility_cli.sh <clothfit> <source dir>. Bad --ao-weighting, --vis-samples,
# --vis-bounces and --indirect-albedo values fail (fit and evaluate) with an error naming the
# option; no preset is written. The unit tests are tests/test_s9_visibility.cpp (S9Visibility.*).
. "$(dirname "$0")/cli_common.sh"

check() {  # check <option named in the error> <args...>
  local name=$1; shift
  err=$("$BIN" --quiet "$@" 2>&1) && fail "$* accepted"
  grep -q -- "$name" <<< "$err" || fail "error of '$*' does not name $name: $err"
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
check --vis-uv-size fit --references "$TMP/ref.exr" --scenes "$SCENE" --vis-uv-size 64 --out "$TMP/f.json"
[ ! -e "$TMP/f.json" ] || fail "preset written despite --vis-uv-size without a term"

# Session 13: a card's "visibility" block. render-preview --light-map-out writes the fabric's
# baked light map (RGB irradiance, the uv box in the metadata); a card without the block is
# refused before any work, nothing written; a fit records that it ran the albedo pass.
python3 - "$SCENE" "$TMP/lm.json" <<'PY'
import json, os, sys
c = json.load(open(sys.argv[1]))
c["gltf"] = os.path.join(os.path.dirname(os.path.abspath(sys.argv[1])), c["gltf"])
c["width"] = c["height"] = 48
c["visibility"] = {"shadows": True, "light_map": {"size": 16, "samples": 8, "hit_samples": 2}}
json.dump(c, open(sys.argv[2], "w"))
PY
printf '{"schema":"clothfit.preset","version":1,"model":"standard","parameters":{"base_color":[0.5,0.4,0.3],"roughness":0.6,"metalness":0}}' > "$TMP/std.json"
"$BIN" --quiet render-preview --scene "$TMP/lm.json" --material "$TMP/std.json" --out "$TMP/lm.png"   --light-map-out "$TMP/lm.exr" > /dev/null 2>&1 || fail "render-preview --light-map-out failed"
[ -s "$TMP/lm.exr" ] || fail "no light map written"
if command -v oiiotool > /dev/null; then
  grep -q "clothfit:uv_box" <<< "$(oiiotool --info -v "$TMP/lm.exr")" || fail "light map without its uv box"
  grep -Eq "16 x +16," <<< "$(oiiotool --info "$TMP/lm.exr")" || fail "light map is not 16 x 16"
fi
check -- --light-map-out render-preview --scene "$SCENE" --material "$TMP/std.json" --out "$TMP/x.png"   --light-map-out "$TMP/x.exr"
check -- --light-map-out render-preview --scene "$TMP/lm.json" --material "$TMP/std.json" --out "$TMP/x.png"   --light-map-out "$TMP/x.exr" --no-card-visibility
[ ! -e "$TMP/x.exr" ] && [ ! -e "$TMP/x.png" ] || fail "output written despite a --light-map-out error"
# Session 15: a woven fit on a card with a light map runs two passes (the light map re-baked with
# the first pass's albedo); fit.woven_paths keeps both passes' paths, the first pass's (with the
# cloth-basin start) under "first pass: ", the second's under "albedo pass: ".
# fit_card <card> <spp> <model> <iterations> <name>: a canvas reference of the card, then a fit
# of it at level 2 to $TMP/<name>.json (exit 0 or 3 = flagged accepted; the log on failure).
fit_card() {
  "$BIN" --quiet render-reference --scene "$1" --fabric "$SRC/datasets/fabrics/canvas.json" \
    --spp "$2" --out "$TMP/$5.ref.exr" > /dev/null 2>&1 || fail "render-reference of $1 failed"
  "$BIN" --quiet fit --references "$TMP/$5.ref.exr" --scenes "$1" --model "$3" \
    --max-iterations "$4" --level 2 --out "$TMP/$5.json" > "$TMP/$5.log" 2>&1
  local rc=$?
  [ $rc -eq 0 ] || [ $rc -eq 3 ] || fail "$3 fit on $1 exited $rc: $(cat "$TMP/$5.log")"
}
fit_card "$TMP/lm.json" 2 woven 2 lmfit
python3 - "$TMP/lmfit.json" <<'PY' || fail "fit.woven_paths does not keep both passes"
import json, sys
f = json.load(open(sys.argv[1]))["fit"]
assert f.get("light_map_albedo_pass") is True, f.get("light_map_albedo_pass")
names = [p["path"] for p in f["woven_paths"]]
# session 26: the whole path once per free start roughness (0.6 first) and from the cloth
# basin, each branch's stages named after it, then a second round from the best
assert names[0] == "first pass: start 0.6: two-stage", names
assert "first pass: start 0.3: two-stage" in names, names
assert "first pass: cloth basin: cloth-basin" in names, names
assert "first pass: second round: two-stage" in names, names
assert "albedo pass: two-stage" in names, names
# session 18: each pass has the rough-diffuse stage; session 25: then the two lobe-shape stages
# (this fit has no --fabric, so woven's GGX lobes with their anisotropy free)
assert "albedo pass: rough-diffuse" in names and "first pass: second round: rough-diffuse" in names, names
assert "first pass: start 0.6: rough-diffuse" not in names, names  # branches: lobe shape only
assert names[-3:] == ["albedo pass: rough-diffuse", "albedo pass: lobe-shape",
                      "albedo pass: lobe-shape+share"], names
assert "first pass: second round: lobe-shape+share" in names, names
assert all(n.startswith(("first pass: ", "albedo pass: ")) for n in names), names
PY
# Session 21: the fit's recorded errors are the preset's as drawn: after the albedo pass, fit.rmse
# is measured with the light map bouncing the preset's own albedo, as evaluate bakes it (before,
# it was the first pass's albedo, and the two differed in the 5th digit on the drape).
python3 - "$SRC/datasets/scenes/drape.json" "$TMP/drape.json" <<'PY'
import json, os, sys
c = json.load(open(sys.argv[1]))
c["gltf"] = os.path.join(os.path.dirname(os.path.abspath(sys.argv[1])), c["gltf"])
c["width"] = c["height"] = 48
c["visibility"]["light_map"].update({"size": 32, "samples": 16, "hit_samples": 2})
json.dump(c, open(sys.argv[2], "w"))
PY
fit_card "$TMP/drape.json" 4 standard 20 dfit
"$BIN" --quiet evaluate --preset "$TMP/dfit.json" --json > "$TMP/deval.json" 2>&1 || fail "evaluate of the drape fit failed: $(cat "$TMP/deval.json")"
python3 - "$TMP/dfit.json" "$TMP/deval.json" <<'PY' || fail "fit.rmse is not the preset's own error"
import json, sys
f = json.load(open(sys.argv[1]))["fit"]
e = json.load(open(sys.argv[2]))["rmse"]
assert f.get("light_map_albedo_pass") is True, f.get("light_map_albedo_pass")
assert abs(f["rmse"] - e) <= 1e-6 * e, "fit.rmse %.12g, evaluate %.12g" % (f["rmse"], e)
PY
# a bad block is named with the card
python3 -c "
import json,sys; c=json.load(open('$TMP/lm.json')); c['visibility']={'light_map':{'size':0}}; json.dump(c,open('$TMP/bad.json','w'))"
check visibility.light_map.size render-preview --scene "$TMP/bad.json" --material "$TMP/std.json" --out "$TMP/x.png"
echo "ok"

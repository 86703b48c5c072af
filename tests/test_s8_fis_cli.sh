#!/usr/bin/env bash
# s8-fis-cpp: the command-line side of woven FIS and of the fits' IBL engine:
# test_s8_fis_cli.sh <clothfit> <source dir>. Bad --ibl-engine / --woven-ibl values and a bad
# preset "woven" IBL field fail with an error naming the option or field; no preset is written.
. "$(dirname "$0")/cli_common.sh"

err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --ibl-engine vulkan \
      --out "$TMP/f.json" 2>&1) && fail "fit --ibl-engine vulkan accepted"
grep -q -- "--ibl-engine" <<< "$err" || fail "fit error does not name --ibl-engine: $err"
[ ! -e "$TMP/f.json" ] || fail "preset written despite a bad --ibl-engine"

err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
      --woven-ibl exact --out "$TMP/f.json" 2>&1) && fail "fit --woven-ibl exact accepted"
grep -q -- "--woven-ibl" <<< "$err" || fail "fit error does not name --woven-ibl: $err"

err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
      --fis-taps 0 --out "$TMP/f.json" 2>&1) && fail "fit --fis-taps 0 accepted"
grep -q -- "--fis-taps" <<< "$err" || fail "fit error does not name --fis-taps: $err"

# FIS exists on the three.js engine only: asking for it on Filament's is an error (before any
# reference is read).
err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
      --ibl-engine filament --woven-ibl fis --out "$TMP/f.json" 2>&1) \
  && fail "fit --woven-ibl fis --ibl-engine filament accepted"
grep -q "three.js IBL engine" <<< "$err" || fail "fis on filament: $err"
[ ! -e "$TMP/f.json" ] || fail "preset written despite an error"

# Options that would be ignored are errors (session 9): FIS options on another model or
# without --woven-ibl fis.
for args in "--model standard --woven-ibl fis" "--model standard --fis-taps 8" \
            "--model woven --fis-taps 8" "--model woven --woven-ibl split --fis-diffuse-taps 2"; do
  # shellcheck disable=SC2086
  err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" $args \
        --out "$TMP/f.json" 2>&1) && fail "fit $args accepted"
  grep -q -- "only" <<< "$err" || fail "fit $args: $err"
  [ ! -e "$TMP/f.json" ] || fail "preset written despite fit $args"
done

err=$("$BIN" --quiet evaluate --preset "$TMP/none.json" --ibl-engine metal 2>&1) \
  && fail "evaluate --ibl-engine metal accepted"
grep -q -- "--ibl-engine" <<< "$err" || fail "evaluate error does not name --ibl-engine: $err"

printf '{"schema":"clothfit.preset","version":1,"model":"woven","parameters":{},"woven":{"ibl":"fis","fis_taps":100}}' > "$TMP/w.json"
err=$("$BIN" render-preview --scene "$SCENE" --material "$TMP/w.json" --out "$TMP/p.png" 2>&1) \
  && fail "fis_taps 100 accepted"
grep -q "woven.fis_taps" <<< "$err" || fail "error does not name woven.fis_taps: $err"
grep -q "w.json" <<< "$err" || fail "error does not name the file: $err"
printf '{"schema":"clothfit.preset","version":1,"model":"woven","parameters":{},"woven":{"ibl":"fast"}}' > "$TMP/w.json"
err=$("$BIN" render-preview --scene "$SCENE" --material "$TMP/w.json" --out "$TMP/p.png" 2>&1) \
  && fail "ibl fast accepted"
grep -q "woven.ibl" <<< "$err" || fail "error does not name woven.ibl: $err"
# The fit's sampled caches carry the FIS table (review s8: fit/image_fit.cpp Subset copies
# yarn_radiance and geometryRoughness; a dropped table would silently fall back to the split
# sum): `evaluate` of a FIS preset against render-preview's FIS frame of the same preset is
# ~0, and the split-sum preset against that frame is not. A 64 x 64 copy of the sphere card.
sed -e "s#\"sphere.gltf\"#\"$SRC/datasets/scenes/sphere.gltf\"#" -e 's/"width": 256/"width": 64/' \
    -e 's/"height": 256/"height": 64/' "$SCENE" > "$TMP/small.json"
W='"parameters":{"base_color":[0.2,0.3,0.1],"specular_color":[0.6,0.55,0.5],"roughness":0.6,"anisotropy":0.7}'
printf '{"schema":"clothfit.preset","version":1,"model":"woven",%s,"woven":{"ibl":"fis"},"fit":{"ibl_engine":"threejs"}}' "$W" > "$TMP/fis.json"
printf '{"schema":"clothfit.preset","version":1,"model":"woven",%s,"fit":{"ibl_engine":"threejs"}}' "$W" > "$TMP/split.json"
"$BIN" --quiet render-preview --scene "$TMP/small.json" --material "$TMP/fis.json" \
    --ibl-engine threejs --out "$TMP/fis.exr" || fail "render-preview of the FIS preset failed"
for stride in 1 2; do
  out=$("$BIN" --quiet evaluate --preset "$TMP/fis.json" --references "$TMP/fis.exr" \
        --scenes "$TMP/small.json" --stride $stride --level 0 --json) || fail "evaluate fis: $out"
  python3 -c 'import json,sys; j=json.loads(sys.argv[1]); assert j["woven_ibl"]=="fis" and j["ibl_engine"]=="threejs", j; assert j["rmse"] < 1e-4, j["rmse"]' "$out" \
    || fail "FIS preset vs its own FIS frame (stride $stride): $out"
done
out=$("$BIN" --quiet evaluate --preset "$TMP/split.json" --references "$TMP/fis.exr" \
      --scenes "$TMP/small.json" --stride 1 --level 0 --json) || fail "evaluate split: $out"
python3 -c 'import json,sys; j=json.loads(sys.argv[1]); assert j["woven_ibl"]=="split", j; assert j["rmse"] > 1e-3, j["rmse"]' "$out" \
  || fail "split preset vs the FIS frame should differ: $out"
# On Filament's engine the FIS preset is evaluated with the split sum, and evaluate says so.
err=$("$BIN" evaluate --preset "$TMP/fis.json" --references "$TMP/fis.exr" --scenes "$TMP/small.json" \
      --ibl-engine filament --stride 1 --level 0 --json 2>&1 >/dev/null) || fail "evaluate on filament: $err"
grep -q "split sum" <<< "$err" || fail "evaluate on filament does not say FIS is off: $err"
echo "PASS"

#!/usr/bin/env bash
# Session 27: the user audit of fit, evaluate, render-preview and tonemap, one block per item:
# test_s27_fit_cli.sh <clothfit> <source dir>. Display-encoded references refused (1), outputs
# that are inputs refused (2), unwritable output directories refused before any work (3),
# tonemap's --exposure (4) and output name (5), woven as the fit's default model (6), woven's
# parameters without effect (7), nothing to fit (8), an implausible noise floor (9), option
# values checked whatever the model (10), evaluate's hint for a preset's missing references (11).
. "$(dirname "$0")/cli_common.sh"
D=$SRC/datasets
# A 64 x 64 copy of the sphere card and a reference of a smooth material on it (GGX gold):
# each fit below takes well under a second.
sed -e "s#\"sphere.gltf\"#\"$D/scenes/sphere.gltf\"#" -e 's/"width": 256/"width": 64/' \
    -e 's/"height": 256/"height": 64/' "$SCENE" > "$TMP/small.json"
CARD=$TMP/small.json
for seed in 1 2; do
  "$BIN" --quiet render-reference --scene "$CARD" --fabric "$D/materials/ggx_conductor.json" \
    --spp 16 --seed $seed --out "$TMP/ref$seed.exr" > /dev/null || fail "render-reference seed $seed"
done
REF=$TMP/ref1.exr
printf '{"schema":"clothfit.preset","version":1,"model":"standard","parameters":{},"fit":{}}' > "$TMP/std.json"
# fit_ok NAME [options]: a short fit on the small card; exit 0 or 3; output in $TMP/NAME.log
fit_ok() {
  local name=$1; shift
  "$BIN" --quiet fit --scenes "$CARD" --level 2 --max-iterations 20 --out "$TMP/$name.json" "$@" \
    > "$TMP/$name.log" 2>&1
  local st=$?
  [ $st = 0 ] || [ $st = 3 ] || fail "fit $name exited $st: $(cat "$TMP/$name.log")"
  return $st
}

# 1. An 8- or 16-bit PNG holds display-encoded values: refused as a reference by fit (also as
# --references2) and evaluate, naming the file and what to give instead.
for depth in uint8 uint16; do
  oiiotool "$REF" --ch R,G,B -d $depth -o "$TMP/ref_$depth.png" || fail "oiiotool $depth"
  err=$("$BIN" --quiet fit --references "$TMP/ref_$depth.png" --scenes "$CARD" --model standard \
        --out "$TMP/f.json" 2>&1) && fail "fit accepted a $depth PNG reference"
  grep -q "ref_$depth.png: a reference must be linear radiance .*$depth png.*give the renderer's linear EXR or HDR" \
    <<< "$err" || fail "fit, $depth PNG: $err"
  [ ! -e "$TMP/f.json" ] || fail "a preset was written for a $depth PNG reference"
  err=$("$BIN" --quiet evaluate --preset "$TMP/std.json" --references "$TMP/ref_$depth.png" \
        --scenes "$CARD" 2>&1) && fail "evaluate accepted a $depth PNG reference"
  grep -q "ref_$depth.png: a reference must be linear radiance" <<< "$err" || fail "evaluate, $depth PNG: $err"
done
err=$("$BIN" --quiet fit --references "$REF" --references2 "$TMP/ref_uint8.png" --scenes "$CARD" \
      --model standard --out "$TMP/f.json" 2>&1) && fail "fit accepted a PNG --references2"
grep -q "ref_uint8.png: a reference must be linear radiance" <<< "$err" || fail "--references2 PNG: $err"

# 2. An output that is an input is refused, before any work, the input untouched: --out over
# --fabric, --references (another spelling of the path), --references2 (a symbolic link) or
# --scenes, an --images file over a reference; render-preview's --out over its --material (by
# a link) and tonemap's output over its input.
mkdir "$TMP/fabrics" && cp "$D/fabrics/canvas.json" "$TMP/fabrics/" && ln -s "$D/weaves" "$TMP/weaves"
err=$(CLOTHFIT_CACHE="$TMP/cache" "$BIN" --quiet fit --fabric "$TMP/fabrics/canvas.json" --scenes "$CARD" \
      --spp 16 --model standard --out "$TMP/fabrics/canvas.json" 2>&1) && fail "--out = --fabric accepted"
grep -q -- "--out .*canvas.json is the same file as --fabric .*canvas.json: refusing to overwrite an input" <<< "$err" \
  || fail "--out = --fabric: $err"
cmp -s "$TMP/fabrics/canvas.json" "$D/fabrics/canvas.json" || fail "the fabric was changed"
[ ! -e "$TMP/cache" ] || fail "references rendered before refusing --out"
ln -s ref2.exr "$TMP/link2.exr"
for args in "--references $REF --out $TMP/../$(basename "$TMP")/ref1.exr" \
            "--references $REF --references2 $TMP/link2.exr --out $TMP/ref2.exr" \
            "--references $REF --out $CARD"; do
  # shellcheck disable=SC2086
  err=$("$BIN" --quiet fit $args --scenes "$CARD" --model standard 2>&1) && fail "fit $args accepted"
  grep -q -- "is the same file as --" <<< "$err" || fail "fit $args: $err"
  grep -q "^fit: level" <<< "$err" && fail "fit $args started before refusing"
done
# Woven's glint map (--weave-maps glint writes OUT.glint.exr next to OUT.weave.exr; session 28).
cp "$REF" "$TMP/g.glint.exr"
err=$("$BIN" --quiet fit --fabric "$TMP/fabrics/canvas.json" --references "$TMP/g.glint.exr" --scenes "$CARD" \
      --model woven --weave-maps glint --out "$TMP/g.json" 2>&1) && fail "a glint map over a reference accepted"
grep -q -- "--out's glint map .*g.glint.exr is the same file as --references" <<< "$err" || fail "glint map over a reference: $err"
cmp -s "$TMP/g.glint.exr" "$REF" || fail "the reference was changed by the glint map"
mkdir "$TMP/imgs" && cp "$REF" "$TMP/imgs/small_preview.exr"
err=$("$BIN" --quiet fit --references "$TMP/imgs/small_preview.exr" --scenes "$CARD" --model standard \
      --images "$TMP/imgs" --out "$TMP/f.json" 2>&1) && fail "an --images file over a reference accepted"
grep -q -- "--images .*small_preview.exr is the same file as --references" <<< "$err" || fail "--images over a reference: $err"
ln -s std.json "$TMP/alias.png"
err=$("$BIN" --quiet render-preview --scene "$CARD" --material "$TMP/std.json" --out "$TMP/alias.png" 2>&1) \
  && fail "render-preview --out = --material accepted"
grep -q -- "--out .*alias.png is the same file as --material" <<< "$err" || fail "render-preview --out = --material: $err"
grep -q '"schema"' "$TMP/std.json" || fail "the material was overwritten"
err=$("$BIN" --quiet tonemap "$TMP/ref_uint8.png" "$TMP/ref_uint8.png" 2>&1) && fail "tonemap output = input accepted"
grep -q "output .*ref_uint8.png is the same file as input" <<< "$err" || fail "tonemap output = input: $err"

# 3. An output directory that takes no new file is an error before any work (fit, its --images,
# render-preview, tonemap), and no probe file is left behind. chmod does not stop root: as
# root the commands run as nobody (setpriv), else this block is skipped.
as=()
if [ "$(id -u)" = 0 ]; then
  if setpriv --reuid=65534 --regid=65534 --clear-groups true 2> /dev/null; then
    as=(setpriv --reuid=65534 --regid=65534 --clear-groups)
    chmod 755 "$TMP"
  else
    as=(skip)
  fi
fi
mkdir "$TMP/ro" && chmod 555 "$TMP/ro"
if [ "${as[0]:-}" = skip ]; then
  echo "SKIP (item 3): running as root without setpriv: a chmod 555 directory cannot be tested"
else
  # (no HDR map and no table cache: nothing of root's home is read, so that without the check
  # the command would run to its end and fail there)
  run() { CLOTHFIT_DATA="$TMP/nodata" CLOTHFIT_TABLE_CACHE=off "${as[@]}" "$BIN" --quiet "$@" 2>&1; }
  err=$(run fit --references "$REF" --scenes "$CARD" --model standard --out "$TMP/ro/f.json") \
    && fail "fit into a read-only directory accepted"
  grep -q -- "--out: .*ro/f.json: output directory .*ro is not writable (Permission denied)" <<< "$err" \
    || fail "fit --out read-only: $err"
  grep -q "^fit: level" <<< "$err" && fail "fit started before refusing the read-only --out"
  err=$(run fit --references "$REF" --scenes "$CARD" --model standard --images "$TMP/ro/imgs" \
        --out "$TMP/ro/f.json") && fail "fit --images in a read-only directory accepted"
  grep -q "not writable" <<< "$err" || fail "fit --images read-only: $err"
  err=$(run render-preview --scene "$CARD" --material "$TMP/std.json" --out "$TMP/ro/p.png") \
    && fail "render-preview into a read-only directory accepted"
  grep -q -- "--out: .*ro/p.png: output directory .*ro is not writable" <<< "$err" || fail "render-preview read-only: $err"
  err=$(run tonemap "$REF" "$TMP/ro/t.png") && fail "tonemap into a read-only directory accepted"
  grep -q "output: .*ro/t.png: output directory .*ro is not writable" <<< "$err" || fail "tonemap read-only: $err"
fi
[ -z "$(ls -A "$TMP/ro")" ] || fail "files left in the read-only directory: $(ls -A "$TMP/ro")"
err=$("$BIN" --quiet fit --references "$REF" --scenes "$CARD" --model standard --out "$TMP/imgs" 2>&1) \
  && fail "--out naming a directory accepted"
grep -q -- "--out: .*imgs is a directory" <<< "$err" || fail "--out a directory: $err"
mkdir "$TMP/w"
"$BIN" --quiet tonemap "$REF" "$TMP/w/t.png" || fail "tonemap into a writable directory"
[ "$(ls -A "$TMP/w")" = t.png ] || fail "the write probe left files: $(ls -A "$TMP/w")"

# 4. tonemap --exposure: a finite number > 0, as compare --exposure (was: 0, -1, nan silently 1).
for e in 0 -1 nan inf; do
  err=$("$BIN" --quiet tonemap "$REF" "$TMP/e.png" --exposure "$e" 2>&1) && fail "tonemap --exposure $e accepted"
  grep -q -- "--exposure: must be a finite number > 0" <<< "$err" || fail "tonemap --exposure $e: $err"
done
[ ! -e "$TMP/e.png" ] || fail "tonemap wrote an image despite a bad --exposure"
"$BIN" --quiet tonemap "$REF" "$TMP/e.png" --exposure 2 || fail "tonemap --exposure 2"

# 5. tonemap writes PNG only, so the output must be named .png (any case).
for out in o.exr o.jpg o; do
  err=$("$BIN" --quiet tonemap "$REF" "$TMP/$out" 2>&1) && fail "tonemap to $out accepted"
  grep -q "output '.*$out': must end in .png" <<< "$err" || fail "tonemap to $out: $err"
  [ ! -e "$TMP/$out" ] || fail "tonemap wrote $out"
done
"$BIN" --quiet tonemap "$REF" "$TMP/o.PNG" || fail "tonemap to .PNG"
[ "$(head -c 4 "$TMP/o.PNG" | tail -c 3)" = PNG ] || fail "o.PNG is not a PNG"

# 6. The fit's default model is woven, and --help says so.
help=$("$BIN" fit --help) || fail "fit --help exited $?"
grep -q -- "--model .*woven (default)" <<< "$help" || fail "fit --help does not state the default model"
fit_ok default --references "$REF"
python3 -c 'import json,sys; m=json.load(open(sys.argv[1]))["model"]; sys.exit(0 if m == "woven" else "model %s" % m)' \
  "$TMP/default.json" || fail "the default model is not woven"

# 7. woven at anisotropy 0 (held there, warp_share and twist started on their bounds): both
# yarn lobes are one isotropic lobe, warp_share and twist have no effect: a note, no WARNING,
# fit.no_effect, and warp_share's bound unflagged in fit.at_bound.
fit_ok noeffect --references "$REF" --model woven --start anisotropy=0,warp_share=0,twist=90 \
  --lock anisotropy,sheen_color,sheen_roughness,diffuse_roughness
grep -q "^fit: note: warp_share, twist: no effect at anisotropy 0" "$TMP/noeffect.log" || fail "no note: $(cat "$TMP/noeffect.log")"
grep -q "WARNING: \(warp_share\|twist\)" "$TMP/noeffect.log" && fail "a bound without effect was flagged: $(cat "$TMP/noeffect.log")"
python3 - "$TMP/noeffect.json" <<'PY' || fail "fit.no_effect / fit.at_bound"
import json, sys
f = json.load(open(sys.argv[1]))["fit"]
assert f["no_effect"] == {"parameters": ["warp_share", "twist"], "why": "at anisotropy 0"}, f.get("no_effect")
ws = [b for b in f["at_bound"] if b["name"] == "warp_share"]
assert ws and not ws[0]["flagged"], f["at_bound"]
PY

# 8. Every parameter locked: nothing to fit, said (a WARNING, exit 0, fit.nothing_fitted).
"$BIN" --quiet fit --references "$REF" --scenes "$CARD" --level 2 --model standard \
  --lock metalness,roughness,base_color --out "$TMP/locked.json" > "$TMP/locked.log" 2>&1 \
  || fail "fit with every parameter locked exited $?: $(cat "$TMP/locked.log")"
grep -q "^fit: WARNING: nothing to fit: every parameter of standard is locked (metalness,roughness,base_color:" \
  "$TMP/locked.log" || fail "no nothing-to-fit warning: $(cat "$TMP/locked.log")"
python3 -c 'import json,sys; sys.exit(0 if json.load(open(sys.argv[1]))["fit"].get("nothing_fitted") is True else 1)' \
  "$TMP/locked.json" || fail "fit.nothing_fitted not recorded"

# 9. A --references2 of something else (a constant image): its noise floor above the fit's
# error is warned about and recorded; a true second seed is not.
oiiotool --pattern constant:color=5,5,5 64x64 3 -d float -o "$TMP/other.exr" || fail "oiiotool constant"
fit_ok floor_bad --references "$REF" --references2 "$TMP/other.exr" --model standard
grep -q "^fit: WARNING: small.json: noise floor .* is above the fit's rmse .*floor looks wrong: .*other.exr and .*ref1.exr do not look like two renders" \
  "$TMP/floor_bad.log" || fail "no noise-floor warning: $(cat "$TMP/floor_bad.log")"
python3 -c 'import json,sys; sys.exit(0 if json.load(open(sys.argv[1]))["fit"]["scenes"][0].get("noise_floor_suspect") is True else 1)' \
  "$TMP/floor_bad.json" || fail "fit.scenes[0].noise_floor_suspect not recorded"
fit_ok floor_ok --references "$REF" --references2 "$TMP/ref2.exr" --model standard
grep -q "noise floor" "$TMP/floor_ok.log" || fail "no noise floor with a second seed: $(cat "$TMP/floor_ok.log")"
grep -q "floor looks wrong" "$TMP/floor_ok.log" && fail "a true second seed was warned about: $(cat "$TMP/floor_ok.log")"

# 10. --variant, --space, --loss and --sheen-default values are checked whatever the model.
for opt in --variant --space --loss --sheen-default; do
  err=$("$BIN" --quiet fit --model standard $opt bogus --references "$REF" --scenes "$CARD" \
        --out "$TMP/f.json" 2>&1) && fail "fit --model standard $opt bogus accepted"
  grep -q -- "$opt: bogus not in" <<< "$err" || fail "fit $opt bogus: $err"
done
[ ! -e "$TMP/f.json" ] || fail "a preset was written despite a bad option"

# 11. evaluate of a preset whose own references are not on this machine: the error, and a hint
# naming the preset's field and what to do.
printf '{"schema":"clothfit.preset","version":1,"model":"standard","parameters":{},
"fit":{"scenes":[{"scene":"%s","reference":"%s/gone.exr"}]},
"provenance":{"fabric":"datasets/fabrics/canvas.json"}}' "$CARD" "$TMP" > "$TMP/gone.json"
err=$("$BIN" --quiet evaluate --preset "$TMP/gone.json" 2>&1) && fail "evaluate without the references accepted"
grep -q "gone.exr: cannot open image file" <<< "$err" || fail "evaluate: the error is gone: $err"
grep -q "hint: .*gone.json: field 'fit.scenes\[0\].reference' names a file that is not on this machine.*clothfit fit --fabric datasets/fabrics/canvas.json.*render-references.*--references and --scenes" \
  <<< "$err" || fail "evaluate: no hint: $err"
echo "PASS: s27"

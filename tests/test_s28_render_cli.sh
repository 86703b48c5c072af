#!/usr/bin/env bash
# Session 28: the user audit of render-reference, render-references, render-preview, lut and
# the hand-written inputs, one block per item: test_s28_render_cli.sh <clothfit> <source dir>.
# render-reference's output refused over an input or under a non-EXR name (1) and its scene's
# repairs reported (2); render-references checks every input before the first render (3); lut's
# outputs, and two spellings of one new file (4); environment maps that are PNGs or missing
# files (5); --help defaults and CLOTHFIT_PROGRESS=0 (6); bench's --width and --count (7);
# render-preview's upper-case extension (8); --light-map-out's help (9); the reference cache key
# and the fabric's own weave file (10).
. "$(dirname "$0")/cli_common.sh"
D=$SRC/datasets
BIN=$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")  # the blocks below cd
# A 16 x 16 copy of the sphere card (no environment: nothing to install) and a fabric beside it
# with its own weave file.
mkdir -p "$TMP/card" "$TMP/fab"
sed -e "s#\"sphere.gltf\"#\"$D/scenes/sphere.gltf\"#" -e 's/"width": 256/"width": 16/' \
    -e 's/"height": 256/"height": 16/' "$SCENE" > "$TMP/card/small.json"
CARD=$TMP/card/small.json
cp "$D/weaves/cotton_canvas.weave" "$TMP/fab/my.weave"
printf '{"format":"clothfit-fabric","version":1,"name":"mine","model":"irawan","preset":"cotton_canvas","weave_file":"my.weave","uv_repeats":60}' \
  > "$TMP/fab/f.json"
FAB=$TMP/fab/f.json
render() { "$BIN" --quiet render-reference --scene "$CARD" --fabric "$FAB" --spp 2 "$@"; }

# (1) --out: an input is never replaced (before, `--out f.json` rendered, then wrote the EXR over
# the fabric), and the name says EXR (before, `--out x.png` received EXR bytes).
cp "$FAB" "$TMP/fab/f.orig"
err=$(render --out "$FAB" 2>&1) && fail "--out over the fabric accepted"
grep -q -- "--out: '.*f.json' must end in .exr" <<< "$err" || fail "--out over the fabric: $err"
cmp -s "$FAB" "$TMP/fab/f.orig" || fail "the fabric file was changed"
err=$(render --out "$TMP/x.png" 2>&1) && fail "--out x.png accepted"
grep -q "must end in .exr" <<< "$err" || fail "--out x.png: $err"
[ ! -e "$TMP/x.png" ] || fail "--out x.png was written"
err=$(render --out "$TMP" 2>&1) && fail "--out a directory accepted"
# the card's environment map is an input too
oiiotool --pattern constant:color=0.5,0.5,0.5 16x8 3 -d half -o "$TMP/card/env.exr" || fail "oiiotool"
cp "$TMP/card/env.exr" "$TMP/card/env.orig"
sed -e 's#"background"#"environment": {"path": "env.exr"}, "background"#' "$CARD" > "$TMP/card/env.json"
err=$("$BIN" --quiet render-reference --scene "$TMP/card/env.json" --fabric "$FAB" --spp 2 \
  --out "$TMP/card/env.exr" 2>&1) && fail "--out over the environment map accepted"
grep -q "same file as --scene's environment.path" <<< "$err" || fail "--out over the map: $err"
cmp -s "$TMP/card/env.exr" "$TMP/card/env.orig" || fail "the environment map was changed"
render --out "$TMP/ok.EXR" > /dev/null || fail "render-reference --out ok.EXR exited $?"
[ -s "$TMP/ok.EXR" ] || fail "no image"

# (2) The loader's repairs are reported, as render-preview does (before: silent).
python3 - "$D/scenes/sphere.gltf" "$TMP/card/nonormal.gltf" <<'PY' || fail "python"
import json, sys
g = json.load(open(sys.argv[1]))
for m in g["meshes"]:
    for p in m["primitives"]:
        p["attributes"].pop("NORMAL", None)
json.dump(g, open(sys.argv[2], "w"))
PY
sed -e "s#\"$D/scenes/sphere.gltf\"#\"nonormal.gltf\"#" "$CARD" > "$TMP/card/nn.json"
err=$("$BIN" render-reference --scene "$TMP/card/nn.json" --fabric "$D/materials/lambert.json" --spp 2 \
  --out "$TMP/nn.exr" 2>&1 >/dev/null) || fail "render without normals exited $?"
grep -q "warning: .*nonormal.gltf: .*no NORMAL attribute" <<< "$err" || fail "no repair warning: $err"
err=$("$BIN" --quiet render-reference --scene "$TMP/card/nn.json" --fabric "$D/materials/lambert.json" --spp 2 \
  --out "$TMP/nn.exr" 2>&1 >/dev/null) || fail "quiet render without normals exited $?"
[ -z "$err" ] || fail "--quiet printed: $err"

# (3) render-references: every input is checked before the first render. Before, the first
# fabric's references were rendered (and cached) before a missing second fabric, a bad target
# item of the last scene or an adaptive budget that is not a multiple of 16 failed.
export CLOTHFIT_CACHE=$TMP/cache
M=$D/materials/lambert.json
refs() { "$BIN" --quiet render-references --width 8 "$@"; }
err=$(refs --fabrics "$M,$TMP/none.json" --seeds 1 2>&1) && fail "a missing fabric accepted"
grep -q "none.json" <<< "$err" || fail "missing fabric not named: $err"
err=$(refs --fabrics "$M" --seeds 1 --spp 32 --target-error "sphere=0.05,drape=0.05,swatch=abc" 2>&1) \
  && fail "a bad target item accepted"
grep -q -- "--target-error: 'abc'" <<< "$err" || fail "bad target item: $err"
err=$(refs --fabrics "$M" --seeds 1 --target-error 0.05 --spp 40 2>&1) \
  && fail "an adaptive budget of 40 accepted"
grep -q -- "--spp: with --target-error the budget must be a multiple of 16 >= 32, got 40" <<< "$err" \
  || fail "adaptive budget: $err"
# a target item that names no task (a misspelt scene) is an error, not ignored
err=$(refs --fabrics "$M" --seeds 1 --spp 32 --dry-run \
  --target-error "sphere=0.05,drape=0.05,swatch=0.05,lambert/drap=0.01" 2>&1) && fail "an unused target item accepted"
grep -q -- "--target-error: item 'lambert/drap=0.01' names no task of this run (sphere, drape, swatch, lambert/sphere" <<< "$err" \
  || fail "unused target item: $err"
refs --fabrics "$M" --seeds 1 --spp 32 --dry-run --target-error "sphere=0.05,drape=0.05,swatch=0.05,lambert/drape=0.01" \
  > /dev/null || fail "a used fabric/scene target item refused"
[ ! -e "$TMP/cache" ] || [ -z "$(ls "$TMP/cache")" ] || fail "a refused run rendered: $(ls "$TMP/cache")"
# --seeds: integers only (before: -1 was 2^64 - 1, 1.5 and 1abc were 1, x said "stoull", an
# empty list rendered nothing with status 0)
for s in "-1" "1.5" "1abc" "1,x" "" "," "18446744073709551616"; do
  err=$(refs --fabrics "$M" --seeds "$s" --dry-run 2>&1) && fail "--seeds '$s' accepted: $err"
  grep -q -- "--seeds: '${s#1,}'" <<< "$err" || fail "--seeds '$s': $err"
done
# --fabric-list: a directory is "not a file" (before: "the fabric list is empty"); a UTF-8 byte
# order mark before the first path is dropped (before: "fabric file '<BOM>/...' does not exist").
err=$(refs --fabric-list "$TMP" --dry-run 2>&1) && fail "--fabric-list DIR accepted"
grep -q "the fabric list (--fabric-list) is not a file" <<< "$err" || fail "--fabric-list DIR: $err"
printf '\xef\xbb\xbf%s\n# a comment\n' "$M" > "$TMP/list.txt"
out=$(refs --fabric-list "$TMP/list.txt" --seeds 1 --dry-run) || fail "--fabric-list with a BOM exited $?"
[ "$(wc -l <<< "$out")" -eq 3 ] || fail "--fabric-list with a BOM: $out"
out=$(refs --fabrics "$M" --seeds "0,18446744073709551615" --dry-run) || fail "--seeds 0,2^64-1"
grep -q "sphere.json seed 18446744073709551615" <<< "$out" || fail "largest seed: $out"
[ "$(wc -l <<< "$out")" -eq 6 ] || fail "expected 6 tasks: $out"

# (4) lut: two tables never go to one file, and both are EXRs by name (before, --sheen-out equal
# to --out replaced the DFG LUT, and --out dfg.png received EXR bytes). Two spellings of one new
# file are one file (before, "a.exr" and "./a.exr" compared unequal while neither existed: the
# shared check of fit, render-preview and tonemap too).
(cd "$TMP" && "$BIN" --quiet lut --size 8 --out a.exr --sheen-out ./a.exr > /dev/null 2> err.txt) \
  && fail "lut --out a.exr --sheen-out ./a.exr accepted"
grep -q -- "--sheen-out ./a.exr is the same file as --out a.exr" "$TMP/err.txt" || fail "lut same file: $(cat "$TMP/err.txt")"
[ ! -e "$TMP/a.exr" ] || fail "lut wrote a.exr"
err=$("$BIN" --quiet lut --size 8 --out "$TMP/dfg.png" 2>&1) && fail "lut --out dfg.png accepted"
grep -q -- "--out: '.*dfg.png' must end in .exr" <<< "$err" || fail "lut --out dfg.png: $err"
err=$("$BIN" --quiet lut --size 8 --out "$TMP/d.exr" --sheen-out "$TMP/s.png" 2>&1) && fail "lut --sheen-out s.png accepted"
[ ! -e "$TMP/d.exr" ] || fail "lut wrote --out before refusing --sheen-out"
"$BIN" --quiet lut --size 8 --out "$TMP/d.EXR" --sheen-out "$TMP/s.exr" --sheen-size 4 > /dev/null || fail "lut exited $?"
[ -s "$TMP/d.EXR" ] && [ -s "$TMP/s.exr" ] || fail "lut wrote no tables"
printf '{"schema":"clothfit.preset","version":1,"model":"standard","parameters":{}}' > "$TMP/std.json"
(cd "$TMP" && "$BIN" --quiet render-preview --scene "$CARD" --material std.json --out q.exr \
  --light-map-out ./q.exr > /dev/null 2> err.txt) && fail "render-preview --out q.exr --light-map-out ./q.exr accepted"
grep -q -- "--light-map-out ./q.exr is the same file as --out q.exr" "$TMP/err.txt" \
  || fail "render-preview same file: $(cat "$TMP/err.txt")"

# (5) The card's environment: an 8-bit PNG is refused (before, its display codes were taken for
# radiance, status 0), and so is a missing file the card names by path (before, the procedural
# sky was rendered with a warning to run scripts/fetch-data, status 0); the card, the field and
# the file are named. A missing map *name* still falls back to the sky (a fresh checkout).
oiiotool --pattern constant:color=0.9,0.8,0.7 16x8 3 -d uint8 -o "$TMP/card/sky.png" || fail "oiiotool png"
for name in sky.png nope.exr maps/nope; do
  sed -e "s#\"background\"#\"environment\": {\"path\": \"$name\"}, \"background\"#" "$CARD" > "$TMP/card/e.json"
  err=$("$BIN" --quiet render-reference --scene "$TMP/card/e.json" --fabric "$D/materials/lambert.json" \
    --spp 2 --out "$TMP/e.exr" 2>&1) && fail "render-reference with environment '$name' accepted"
  grep -q "e.json: field 'environment.path': .*$(basename "$name")" <<< "$err" || fail "render-reference, environment '$name': $err"
  err=$("$BIN" --quiet render-preview --scene "$TMP/card/e.json" --material "$TMP/std.json" \
    --out "$TMP/e.png" 2>&1) && fail "render-preview with environment '$name' accepted"
  grep -q "e.json: field 'environment.path': .*$(basename "$name")" <<< "$err" || fail "render-preview, environment '$name': $err"
  [ ! -e "$TMP/e.exr" ] && [ ! -e "$TMP/e.png" ] || fail "an image was written with environment '$name'"
done
grep -q "must be linear radiance" <<< "$(CLOTHFIT_DATA=$TMP "$BIN" --quiet render-reference \
  --scene "$TMP/card/env.json" --fabric "$D/materials/lambert.json" --spp 2 --out "$TMP/ok2.exr" 2>&1)" \
  && fail "an EXR map refused"
sed -e 's#"background"#"environment": {"path": "no-such-map"}, "background"#' "$CARD" > "$TMP/card/n.json"
err=$(CLOTHFIT_DATA=$TMP "$BIN" render-reference --scene "$TMP/card/n.json" \
  --fabric "$D/materials/lambert.json" --spp 2 --out "$TMP/sky.exr" 2>&1 >/dev/null) \
  || fail "a missing map name failed: $err"
grep -q "using the procedural sky" <<< "$err" || fail "no fallback warning: $err"

# (6) --help shows the defaults, as the README says ("every default shown"; before, none of
# render-reference, render-references, render-preview, lut and stress did), and
# CLOTHFIT_PROGRESS=0 turns the progress bar off (before, any value turned it on).
"$BIN" render-reference --help | grep -q -- "--spp INT:INT in \[1 - 1048576\]=64" || fail "render-reference --spp default"
"$BIN" render-reference --help | grep -q -- "--max-depth INT:INT in \[1 - 64\]=8" || fail "render-reference --max-depth default"
! "$BIN" render-reference --help | grep -q -- "=-1" || fail "render-reference shows a sentinel -1"
"$BIN" render-references --help | grep -q -- "--seeds TEXT=1,2" || fail "render-references --seeds default"
"$BIN" render-preview --help | grep -q -- "--ibl-engine TEXT:{auto,threejs,filament}=filament" || fail "render-preview --ibl-engine default"
"$BIN" lut --help | grep -q -- "--size INT:INT in \[2 - 4096\]=128" || fail "lut --size default"
"$BIN" stress --help | grep -q -- "--evals INT:INT in \[1 - 10000000000\]=1000000" || fail "stress --evals default"
err=$(CLOTHFIT_PROGRESS=0 "$BIN" lut --size 8 --out "$TMP/p0.exr" 2>&1 >/dev/null) || fail "lut exited $?"
[ -z "$err" ] || fail "CLOTHFIT_PROGRESS=0 printed: $err"
err=$(CLOTHFIT_PROGRESS=1 "$BIN" lut --size 8 --out "$TMP/p1.exr" 2>&1 >/dev/null) || fail "lut exited $?"
grep -q "lut dfg \[" <<< "$err" || fail "CLOTHFIT_PROGRESS=1 printed no bar: $err"

# (7) bench: a negative --width or --count is a usage error (before, `bench reference --width -5`
# rendered at the card's width and `bench convert --count -3` benchmarked 6 materials).
err=$("$BIN" bench reference --width -5 2>&1) && fail "bench reference --width -5 accepted"
grep -q -- "--width" <<< "$err" || fail "bench --width: $err"
err=$("$BIN" bench convert --count -3 2>&1) && fail "bench convert --count -3 accepted"
grep -q -- "--count" <<< "$err" || fail "bench --count: $err"

# (8) render-preview takes an upper-case extension, as tonemap does (before, "--out P.PNG" was
# "must end in .png or .exr").
"$BIN" --quiet render-preview --scene "$CARD" --material "$TMP/std.json" --out "$TMP/P.PNG" > /dev/null \
  || fail "render-preview --out P.PNG exited $?"
[ "$(head -c 4 "$TMP/P.PNG" | tail -c 3)" = PNG ] || fail "P.PNG is not a PNG"

# (9) --light-map-out's help said "A = 1" of a file with R, G, B only (docs/web.md: "A is not in
# the file").
"$BIN" render-preview --help | tr -s ' \n' ' ' | grep -q "A = 1; metadata" && fail "--light-map-out help claims an alpha channel"
"$BIN" --quiet render-preview --scene "$D/scenes/drape.json" --material "$TMP/std.json" --out "$TMP/d.png" \
  --light-map-out "$TMP/lm.exr" > /dev/null || fail "render-preview --light-map-out exited $?"
oiiotool --info "$TMP/lm.exr" | grep -q "3 channel" || fail "the light map is not R, G, B: $(oiiotool --info "$TMP/lm.exr")"

# (10) The reference cache key hashes the .weave file the fabric names ('weave_file'): before,
# it hashed ../weaves/<preset>.weave, so the references of a fabric with its own weave file were
# reused after that file changed.
before=$(refs --fabrics "$FAB" --seeds 1 --spp 16) || fail "render-references of the fabric exited $?"
[ "$(wc -l <<< "$before")" = 3 ] || fail "expected 3 references: $before"
again=$(refs --fabrics "$FAB" --seeds 1 --spp 16) || fail "render-references again exited $?"
[ "$before" = "$again" ] || fail "the same inputs gave other cache files: $before / $again"
sed -i '0,/kd 0.46 0.40 0.30/s//kd 0.20 0.40 0.60/' "$TMP/fab/my.weave"
cmp -s "$TMP/fab/my.weave" "$D/weaves/cotton_canvas.weave" && fail "the weave file did not change"
after=$(refs --fabrics "$FAB" --seeds 1 --spp 16) || fail "render-references after the change exited $?"
for f in $after; do
  grep -qxF "$f" <<< "$before" && fail "a changed weave file reused the cached $f"
done

echo "PASS: s28 render audit"

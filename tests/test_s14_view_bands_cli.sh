#!/usr/bin/env bash
# Session 14: the fit's view-dependent weave maps from the command line (docs/preview.md
# "View-dependent weave maps"): test_s14_view_bands_cli.sh <clothfit> <source dir>.
# A woven fit of an Irawan fabric with the default maps writes the view bands (the preset's
# weave_maps.view_cosines, the EXR's view{k}.* channels); --no-weave-map-views and the other
# --weave-maps modes do not; --weave-map-view-band outside 0..2 fails naming the option.
# The unit tests are S14ViewBands.* in tests/test_weave_maps.cpp.
. "$(dirname "$0")/cli_common.sh"
FABRIC="$SRC/datasets/fabrics/canvas.json"
"$BIN" --quiet render-reference --scene "$SCENE" --fabric "$FABRIC" --spp 2 \
  --out "$TMP/ref.exr" > /dev/null 2>&1 || fail "render-reference failed"
fit() {  # fit <name> <extra args...>
  local name=$1; shift
  "$BIN" --quiet fit --fabric "$FABRIC" --references "$TMP/ref.exr" --scenes "$SCENE" --model woven \
    --max-iterations 2 --no-cloth-basin --out "$TMP/$name.json" "$@" > "$TMP/$name.log" 2>&1
  local rc=$?
  [ $rc -eq 0 ] || [ $rc -eq 3 ] || fail "fit $name exited $rc: $(cat "$TMP/$name.log")"
}
has_views() {  # has_views <preset> -> prints the cosines' count (0 without)
  python3 -c 'import json,sys; print(len(json.load(open(sys.argv[1]))["weave_maps"].get("view_cosines", [])))' "$1"
}
fit default
[ "$(has_views "$TMP/default.json")" = 3 ] || fail "the default fit wrote no view bands"
grep -q "view2.kd.B" <<< "$(oiiotool --info -v "$TMP/default.weave.exr")" || fail "the EXR has no view2.kd.B channel"
grep -q "clothfit:view_cosines" <<< "$(oiiotool --info -v "$TMP/default.weave.exr")" || fail "the EXR has no clothfit:view_cosines"
fit off --no-weave-map-views
[ "$(has_views "$TMP/off.json")" = 0 ] || fail "--no-weave-map-views wrote view bands"
fit relief --weave-maps relief
[ "$(has_views "$TMP/relief.json")" = 0 ] || fail "--weave-maps relief wrote view bands"
fit band --weave-map-view-band 2
[ "$(has_views "$TMP/band.json")" = 0 ] || fail "--weave-map-view-band wrote view bands"
python3 -c 'import json,sys; s=json.load(open(sys.argv[1]))["weave_maps"]["source"]; assert s["view_band"] == 2 and abs(s["view_band_cosine"] - 0.1127016653792583) < 1e-12, s' \
  "$TMP/band.json" || fail "--weave-map-view-band 2 is not recorded as the grazing band"
err=$("$BIN" --quiet fit --fabric "$FABRIC" --references "$TMP/ref.exr" --scenes "$SCENE" \
  --model woven --weave-map-view-band 3 --out "$TMP/bad.json" 2>&1) && fail "--weave-map-view-band 3 accepted"
grep -q -- "--weave-map-view-band" <<< "$err" || fail "the error does not name --weave-map-view-band: $err"
[ ! -e "$TMP/bad.json" ] || fail "a preset was written for a bad option"
echo "ok"

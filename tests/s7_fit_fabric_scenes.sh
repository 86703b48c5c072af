#!/usr/bin/env bash
# s7-gen: `clothfit fit --fabric F --scenes C --references R` (the fabric bakes the weave maps,
# the image fit uses the given cards and references: a woven refit under another environment),
# fit presets carry weave_maps "uri", and a moved preset directory still previews and
# evaluates; a bad uri is an error naming the preset and the field.
#   s7_fit_fabric_scenes.sh <clothfit> <source dir>
set -uo pipefail
BIN=$1
SRC=$2
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
export CLOTHFIT_CACHE=$TMP/cache

# A 24 x 24 sphere card without an environment (lights only; no HDRI needed).
python3 - "$SRC/datasets/scenes/sphere.json" "$TMP/card.json" <<'PY' || fail "card"
import json, os, sys
src, dst = sys.argv[1:]
c = json.load(open(src))
c["gltf"] = os.path.join(os.path.dirname(os.path.abspath(src)), c["gltf"])
c["width"] = c["height"] = 24
c.pop("environment", None)
json.dump(c, open(dst, "w"))
PY
FAB=$SRC/datasets/fabrics/canvas.json
"$BIN" --quiet render-reference --scene "$TMP/card.json" --fabric "$FAB" --spp 16 --seed 1 \
  --out "$TMP/ref.exr" > /dev/null || fail "render-reference exited $?"

# Errors first.
err=$("$BIN" --quiet fit --fabric "$FAB" --references "$TMP/ref.exr" --model woven --out "$TMP/x.json" 2>&1) \
  && fail "--fabric --references without --scenes accepted"
grep -q -- "--fabric --references needs --scenes" <<< "$err" || fail "unclear error: $err"
err=$("$BIN" --quiet fit --fabric "$FAB" --scenes "$TMP/card.json" --references2 "$TMP/ref.exr" --out "$TMP/x.json" 2>&1) \
  && fail "--references2 without --references accepted"
grep -q -- "--references2 needs --references" <<< "$err" || fail "unclear error: $err"

# The woven refit on the given card and reference, maps from the fabric.
mkdir -p "$TMP/a"
"$BIN" --quiet fit --fabric "$FAB" --scenes "$TMP/card.json" --references "$TMP/ref.exr" \
  --model woven --level 2 --stride 1 --max-iterations 5 --out "$TMP/a/w.json" > "$TMP/fit.txt" 2>&1
st=$?
[ $st -eq 0 ] || [ $st -eq 3 ] || { cat "$TMP/fit.txt" >&2; fail "fit exited $st"; }
grep -q "weave maps: " "$TMP/fit.txt" || fail "no weave maps baked: $(cat "$TMP/fit.txt")"
[ -s "$TMP/a/w.weave.exr" ] || fail "no w.weave.exr next to the preset"
python3 - "$TMP/a/w.json" "$TMP/ref.exr" <<'PY' || fail "preset fields"
import json, sys
p = json.load(open(sys.argv[1]))
w = p["weave_maps"]
assert w["uri"] == "w.weave.exr", w
assert w["file"].startswith("/"), w
assert p["fit"]["scenes"][0]["reference"].endswith("ref.exr"), p["fit"]["scenes"]
PY
"$BIN" --quiet render-preview --scene "$TMP/card.json" --material "$TMP/a/w.json" --out "$TMP/before.exr" \
  > /dev/null || fail "preview before the move exited $?"

# Move the directory and break the absolute "file": preview and evaluate read the "uri".
mkdir -p "$TMP/else/where"
mv "$TMP/a" "$TMP/else/where/b"
python3 - "$TMP/else/where/b/w.json" <<'PY' || fail "edit"
import json, sys
p = json.load(open(sys.argv[1]))
p["weave_maps"]["file"] = "/nonexistent/other-machine/w.weave.exr"
json.dump(p, open(sys.argv[1], "w"))
PY
"$BIN" --quiet render-preview --scene "$TMP/card.json" --material "$TMP/else/where/b/w.json" \
  --out "$TMP/after.exr" > /dev/null || fail "preview after the move exited $?"
grep -q '^PASS' <<< "$(oiiotool --fail 0 --diff "$TMP/before.exr" "$TMP/after.exr")" \
  || fail "the moved preset previews other pixels"
"$BIN" --quiet evaluate --json --preset "$TMP/else/where/b/w.json" > "$TMP/ev.json" \
  || fail "evaluate of the moved preset exited $?"
python3 - "$TMP/else/where/b/w.json" "$TMP/ev.json" <<'PY' || fail "evaluate differs from the fit"
import json, sys
fit = json.load(open(sys.argv[1]))["fit"]["rmse"]
ev = json.load(open(sys.argv[2]))["rmse"]
assert abs(fit - ev) <= 1e-4 * max(fit, 1e-9) + 5e-6, (fit, ev)
PY

# A uri escaping the preset's directory: exit 1, the preset file and the field named.
python3 - "$TMP/else/where/b/w.json" "$TMP/else/where/b/bad.json" <<'PY' || fail "edit"
import json, sys
p = json.load(open(sys.argv[1]))
p["weave_maps"]["uri"] = "../../where/b/w.weave.exr"
json.dump(p, open(sys.argv[2], "w"))
PY
err=$("$BIN" --quiet render-preview --scene "$TMP/card.json" --material "$TMP/else/where/b/bad.json" \
  --out "$TMP/bad.exr" 2>&1) && fail "escaping uri accepted"
grep -q "bad.json: field weave_maps.uri: .* escapes the preset's directory" <<< "$err" \
  || fail "unclear error: $err"
echo "PASS: s7_fit_fabric_scenes"

#!/usr/bin/env bash
# s10-sun: the command-line side of the environment's sun as a directional light (docs/sun.md):
# test_s10_sun_cli.sh <clothfit> <source dir>. Bad --env-sun values (render-preview, fit,
# evaluate), a bad card "environment": {"sun"} and a bad preset fit.env_sun fail with an error
# naming the option or the file and field; no preset or image is written. A fit records
# fit.env_sun. The unit tests are tests/test_s10_sun.cpp (S10Sun.*).
. "$(dirname "$0")/cli_common.sh"

check() {  # check <text the error must contain> <args...>
  local name=$1; shift
  err=$("$BIN" --quiet "$@" 2>&1) && fail "$* accepted"
  grep -q -- "$name" <<< "$err" || fail "error of '$*' does not name $name: $err"
}
cat > "$TMP/std.json" <<'J'
{"schema": "clothfit.preset", "version": 1, "model": "standard", "parameters": {"base_color": [0.5, 0.5, 0.5], "roughness": 0.6, "metalness": 0}}
J
small=$(python3 - "$SCENE" "$TMP" <<'PY'
import json, os, sys
card = json.load(open(sys.argv[1]))
card["gltf"] = os.path.join(os.path.dirname(sys.argv[1]), card["gltf"])
card["width"] = card["height"] = 32
json.dump(card, open(os.path.join(sys.argv[2], "small.json"), "w"))
card["environment"]["sun"] = "maybe"
json.dump(card, open(os.path.join(sys.argv[2], "bad.json"), "w"))
print(os.path.join(sys.argv[2], "small.json"))
PY
)
check "--env-sun" render-preview --scene "$small" --material "$TMP/std.json" --env-sun bogus --out "$TMP/p.png"
check "field 'environment.sun'" render-preview --scene "$TMP/bad.json" --material "$TMP/std.json" --out "$TMP/p.png"
[ ! -e "$TMP/p.png" ] || fail "image written despite a bad option"
"$BIN" --quiet render-reference --scene "$small" --fabric "$SRC/datasets/fabrics/canvas.json" \
  --spp 1 --out "$TMP/ref.exr" > /dev/null 2>&1 || fail "render-reference failed"
check "--env-sun" fit --references "$TMP/ref.exr" --scenes "$small" --model standard --env-sun sometimes --out "$TMP/f.json"
[ ! -e "$TMP/f.json" ] || fail "preset written despite a bad option"
# A fit records its choice; evaluate refuses a bad one naming the preset and the field.
"$BIN" --quiet fit --references "$TMP/ref.exr" --scenes "$small" --model standard --level 2 \
  --max-iterations 2 --env-sun off --out "$TMP/f.json" > /dev/null 2>&1 || [ $? = 3 ] || fail "fit failed"
python3 -c 'import json,sys; v=json.load(open(sys.argv[1]))["fit"].get("env_sun"); sys.exit(0 if v == "off" else "fit.env_sun = %r" % v)' "$TMP/f.json" || fail "fit.env_sun not recorded"
check "--env-sun" evaluate --preset "$TMP/f.json" --env-sun bogus
python3 -c 'import json,sys; p=json.load(open(sys.argv[1])); p["fit"]["env_sun"]="maybe"; json.dump(p, open(sys.argv[2], "w"))' "$TMP/f.json" "$TMP/g.json"
check "field 'fit.env_sun'" evaluate --preset "$TMP/g.json"
"$BIN" --quiet evaluate --preset "$TMP/f.json" > /dev/null 2>&1 || fail "evaluate of a good preset failed"
# s21-panels: the mode "panels" is accepted everywhere auto is, recorded by the fit, reused by
# evaluate, and render-preview says what it split (the panels line: "panels: N").
"$BIN" --quiet fit --references "$TMP/ref.exr" --scenes "$small" --model standard --level 2 \
  --max-iterations 2 --env-sun panels --out "$TMP/fp.json" > /dev/null 2>&1 || [ $? = 3 ] || fail "fit --env-sun panels failed"
python3 -c 'import json,sys; v=json.load(open(sys.argv[1]))["fit"].get("env_sun"); sys.exit(0 if v == "panels" else "fit.env_sun = %r" % v)' "$TMP/fp.json" || fail "fit.env_sun panels not recorded"
out=$("$BIN" --quiet evaluate --preset "$TMP/fp.json" --json 2>&1) || fail "evaluate of a panels preset failed: $out"
echo "$out" | python3 -c 'import json,sys; v=json.load(sys.stdin).get("env_sun"); sys.exit(0 if v == "panels" else "env_sun = %r" % v)' \
  || fail "evaluate does not reuse fit.env_sun panels"
out=$("$BIN" render-preview --scene "$small" --material "$TMP/std.json" --env-sun panels --out "$TMP/pp.png" 2>&1) \
  || fail "render-preview --env-sun panels failed: $out"
grep -q "panels: [0-9]" <<< "$out" || fail "render-preview --env-sun panels does not report the panels: $out"
# With the studio map installed (scripts/fetch-data), its four softboxes are found.
if [ -f "${CLOTHFIT_DATA:-$HOME/.cache/clothfit}/hdri/studio.exr" ]; then
  grep -q "panels: 4;" <<< "$out" || fail "render-preview --env-sun panels on the studio map: $out"
fi
# Review s10: evaluate reports a woven "ibl": "bent" preset as bent (it had said split), and a
# bad fit.sheen_tilt_degrees names the preset and the field.
python3 - "$TMP/f.json" "$TMP" <<'PY'
import json, os, sys
p = json.load(open(sys.argv[1]))
w = dict(p, model="woven", parameters={}, woven={"ibl": "bent"})
json.dump(w, open(os.path.join(sys.argv[2], "w.json"), "w"))
t = dict(p); t["fit"] = dict(p["fit"], sheen_tilt_degrees=500)
json.dump(t, open(os.path.join(sys.argv[2], "t500.json"), "w"))
t["fit"]["sheen_tilt_degrees"] = 10  # a standard preset: no sheen lobe to tilt
json.dump(t, open(os.path.join(sys.argv[2], "tstd.json"), "w"))
PY
out=$("$BIN" --quiet evaluate --preset "$TMP/w.json" --json 2>&1) || fail "evaluate of a bent preset failed: $out"
echo "$out" | python3 -c 'import json,sys; v=json.load(sys.stdin).get("woven_ibl"); sys.exit(0 if v == "bent" else "woven_ibl = %r" % v)' \
  || fail "evaluate does not report bent"
check "field 'fit.sheen_tilt_degrees'" evaluate --preset "$TMP/t500.json"
check "field 'fit.sheen_tilt_degrees'" evaluate --preset "$TMP/tstd.json"
echo "ok"

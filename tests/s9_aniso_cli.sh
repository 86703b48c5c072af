#!/usr/bin/env bash
# s9-aniso: the command-line side of the weave maps' anisotropic filtering:
# s9_aniso_cli.sh <clothfit> <source dir>. A bad --map-anisotropy / --map-aniso-rule fails naming
# the option; a preset whose weave_maps.anisotropy is not an integer in [1, 16] fails in
# render-preview and evaluate naming the preset file and the field (before any map is read).
. "$(dirname "$0")/cli_common.sh"

for n in 0 17 2.5 x; do
  err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model woven \
        --map-anisotropy "$n" --out "$TMP/f.json" 2>&1) && fail "fit --map-anisotropy $n accepted"
  grep -q -- "--map-anisotropy" <<< "$err" || fail "fit error does not name --map-anisotropy: $err"
  [ ! -e "$TMP/f.json" ] || fail "preset written despite --map-anisotropy $n"
done

for v in 0 17 2.5 16.0 '"x"'; do
  cat > "$TMP/bad.json" <<JSON
{"schema": "clothfit.preset", "version": 1, "model": "woven", "parameters": {},
 "weave_maps": {"file": "$TMP/missing.weave.exr", "anisotropy": $v}}
JSON
  err=$("$BIN" --quiet render-preview --scene "$SCENE" --material "$TMP/bad.json" \
        --out "$TMP/p.png" 2>&1) && fail "render-preview accepted weave_maps.anisotropy $v"
  grep -q "bad.json" <<< "$err" || fail "render-preview error does not name the file ($v): $err"
  grep -q "weave_maps.anisotropy" <<< "$err" || fail "render-preview error does not name the field ($v): $err"
  err=$("$BIN" --quiet evaluate --scenes "$SCENE" --preset "$TMP/bad.json" \
        --references "$TMP/none.exr" 2>&1) && fail "evaluate accepted weave_maps.anisotropy $v"
  grep -q "weave_maps.anisotropy" <<< "$err" || fail "evaluate error does not name the field ($v): $err"
done

err=$("$BIN" --quiet render-preview --scene "$SCENE" --material "$TMP/bad.json" --out "$TMP/p.png" \
      --map-aniso-rule nvidia 2>&1) && fail "render-preview --map-aniso-rule nvidia accepted"
grep -q -- "--map-aniso-rule" <<< "$err" || fail "error does not name --map-aniso-rule: $err"
# --map-anisotropy on a fit without weave maps would be ignored: an error naming it.
err=$("$BIN" --quiet fit --references "$TMP/none.exr" --scenes "$SCENE" --model standard \
      --map-anisotropy 4 --out "$TMP/f.json" 2>&1) && fail "fit --model standard --map-anisotropy 4 accepted"
grep -q -- "--map-anisotropy" <<< "$err" || fail "error does not name --map-anisotropy: $err"
[ ! -e "$TMP/f.json" ] || fail "preset written despite --map-anisotropy without maps"
echo "s9_aniso_cli: ok"

#!/usr/bin/env bash
# The dependency rules of the folder tree (docs/architecture.md), checked on the includes.
# The link graph is checked at configure time (render/CMakeLists.txt); this test catches an
# include that the linker would not notice (a header-only use).
# Usage: layout_check.sh SOURCE_DIR
set -u
src=${1:?source dir}
cd "$src" || exit 2
fail=0
# rule FOLDER FORBIDDEN-INCLUDE-PREFIX...
rule() {
  local folder=$1; shift
  for bad in "$@"; do
    hits=$(grep -rn --include='*.h' --include='*.cpp' "#include \"$bad" "$folder" || true)
    if [ -n "$hits" ]; then
      echo "layout: $folder must not include $bad:"; echo "$hits"; fail=1
    fi
  done
}
rule brdf render/ fit/ bin/
rule render/scene render/reference render/preview fit/ bin/
rule render/reference render/preview fit/ bin/
rule render/preview render/reference fit/ bin/
rule fit/metrics fit/convert fit/image_fit fit/brdf_fit fit/bench_fit fit/parameter_layout render/reference render/preview bin/
for f in fit/*.h fit/*.cpp; do
  hits=$(grep -n '#include "fit/convert\|#include "bin/' "$f" || true)
  [ -n "$hits" ] && { echo "layout: $f (clothfit_fit) must not include convert or bin:"; echo "$hits"; fail=1; }
done
[ $fail -eq 0 ] && echo "layout: all include rules hold"
exit $fail

# Shared preamble of the CLI shell tests (sourced, not run): `. cli_common.sh` from a test called
# as <test.sh> <clothfit> <source dir> sets BIN, SRC, TMP (removed on exit), SCENE (the sphere
# card) and fail().
set -uo pipefail
BIN=$1
SRC=$(cd "$2" && pwd)
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
SCENE="$SRC/datasets/scenes/sphere.json"

#!/bin/sh
# test_hostile_scripts.sh BUILD — the Lua scripts of tests/data/hostile/lua: each one that
# ever crashed, hung or answered wrongly runs with its expectation on its first line:
#   -- expect: TEXT         exits with status 1 and TEXT in the error (never a signal)
#   -- expect-ok: ...       exits with status 0
#   -- expect-ok-lua5.4: .. exits with status 0, also in the plain lua5.4 interpreter with
#                           the module (when there is one)
#   -- expect-stderr: TEXT  exits with status 0 and TEXT on stderr
# ("-- args: ..." on the second line are its arguments).
BUILD=$1
DIR=$(cd "$(dirname "$0")/../data/hostile/lua" && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
for s in "$DIR"/*.lua; do
  first=$(head -n 1 "$s")
  args=$(sed -n '2s/^-- args: //p' "$s")
  # shellcheck disable=SC2086
  timeout 120 "$BUILD/lugal" "$s" $args > "$T/out" 2> "$T/err"
  rc=$?
  case "$first" in
    "-- expect: "*)
      want=${first#-- expect: }
      if [ "$rc" -ne 1 ] || ! grep -qF "$want" "$T/err"; then
        echo "FAIL $(basename "$s"): status $rc, wanted 1 with \"$want\""; cat "$T/err"; fails=$((fails + 1)); fi ;;
    "-- expect-stderr: "*)
      want=${first#-- expect-stderr: }
      if [ "$rc" -ne 0 ] || ! grep -qF "$want" "$T/err"; then
        echo "FAIL $(basename "$s"): status $rc, wanted 0 with \"$want\" on stderr"; cat "$T/err"; fails=$((fails + 1)); fi ;;
    "-- expect-ok:"*)
      if [ "$rc" -ne 0 ]; then echo "FAIL $(basename "$s"): status $rc"; cat "$T/err"; fails=$((fails + 1)); fi ;;
    "-- expect-ok-lua5.4:"*)
      if [ "$rc" -ne 0 ]; then echo "FAIL $(basename "$s"): status $rc"; cat "$T/err"; fails=$((fails + 1)); fi
      if command -v lua5.4 > /dev/null 2>&1 && [ -f "$BUILD/lugal.so" ] && ! nm -D "$BUILD/lugal.so" 2>/dev/null | grep -q __asan_init; then
        if ! XDG_CACHE_HOME="$T/cache" timeout 300 lua5.4 -e "package.cpath='$BUILD/?.so;'..package.cpath" "$s" > "$T/out" 2> "$T/err"; then
          echo "FAIL $(basename "$s") in lua5.4"; cat "$T/err"; fails=$((fails + 1)); fi
      fi ;;
    *) echo "FAIL $(basename "$s"): no expectation on its first line"; fails=$((fails + 1)) ;;
  esac
done
[ "$fails" -eq 0 ] && echo "hostile scripts: ok"
[ "$fails" -eq 0 ]

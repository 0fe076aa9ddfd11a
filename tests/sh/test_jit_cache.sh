#!/bin/sh
# test_jit_cache.sh BUILD — the -lugal_jit cc disk cache: a cache path with a quote and a
# command substitution in it is just a path (the compiler runs without a shell), a second run
# loads what the first compiled, and a folder that others can write to is refused.
BUILD=$1
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
C="$T/it's \$(touch $T/pwned)"
mkdir -p "$C"
cd "$T" || exit 1
XDG_CACHE_HOME="$C" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out 2>&1 || { cat out; exit 1; }
[ ! -e "$T/pwned" ] || { echo "FAIL: the cache path ran a command"; exit 1; }
n=$(ls "$C/lugal" | grep -c '\.so$')
[ "$n" -ge 2 ] || { echo "FAIL: expected cached kernels, found $n"; exit 1; }
[ "$(stat -c %a "$C/lugal")" = 700 ] || { echo "FAIL: the cache folder is not private"; exit 1; }
XDG_CACHE_HOME="$C" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out2 2>&1 || { cat out2; exit 1; }
[ "$(ls "$C/lugal" | grep -c '\.so$')" = "$n" ] || { echo "FAIL: the second run compiled again"; exit 1; }
grep -q "L2 error" out2
chmod 777 "$C/lugal"
if XDG_CACHE_HOME="$C" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out3 2>&1; then
  echo "FAIL: a world-writable cache was used"; exit 1
fi
grep -q "is not a private folder of this user" out3 || { cat out3; exit 1; }
echo "jit cache: ok"

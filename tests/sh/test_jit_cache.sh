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
# a cached object that is not the kernel asked for, cut short (a power cut after the rename)
# or with flipped bytes is found by its seal before any of its code runs: removed, compiled
# again, the same answer (another kernel's object gave 0 with exit 0, a truncated one failed
# every later run, flipped bytes crashed)
D="$T/plain"
XDG_CACHE_HOME="$D" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out2 2>&1 || { cat out2; exit 1; }
set -- "$D"/lugal/*.so
cp "$1" "$T/first.so"
cp "$2" "$1"
XDG_CACHE_HOME="$D" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out4 2>&1 || { cat out4; exit 1; }
grep -q "damaged or another kernel's (its seal does not match): removed, compiling it again" out4 || { echo "FAIL: a swapped object"; cat out4; exit 1; }
[ "$(grep "L2 error" out4)" = "$(grep "L2 error" out2)" ] || { echo "FAIL: a swapped object changed the answer"; cat out4; exit 1; }
cmp -s "$1" "$T/first.so" || { echo "FAIL: the swapped object was not built again"; exit 1; }
head -c 3000 "$T/first.so" > "$1"
XDG_CACHE_HOME="$D" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out5 2>&1 || { cat out5; exit 1; }
[ "$(grep "L2 error" out5)" = "$(grep "L2 error" out2)" ] || { echo "FAIL: a truncated object"; cat out5; exit 1; }
cmp -s "$1" "$T/first.so" || { echo "FAIL: the truncated object was not built again"; exit 1; }
size=$(stat -c %s "$1")
for at in 200 $((size / 2)) $((size - 200)); do
  cp "$T/first.so" "$1"
  printf '\377\377\377\377' | dd of="$1" bs=1 seek=$at conv=notrunc 2> /dev/null
  XDG_CACHE_HOME="$D" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out6 2>&1 || { echo "FAIL: flipped bytes at $at"; cat out6; exit 1; }
  [ "$(grep "L2 error" out6)" = "$(grep "L2 error" out2)" ] || { echo "FAIL: flipped bytes at $at"; cat out6; exit 1; }
  grep -q "removed, compiling it again" out6 || { echo "FAIL: flipped bytes at $at not found"; cat out6; exit 1; }
done
# two ranks sharing the cache, both finding the swapped object: each removes it and builds it
# again (renames are atomic), the same answer
cp "$2" "$1"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
XDG_CACHE_HOME="$D" timeout 120 mpiexec -n 2 "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out9 2>&1 || { cat out9; exit 1; }
[ "$(grep "L2 error" out9)" = "$(grep "L2 error" out2)" ] || { echo "FAIL: a swapped object on 2 ranks"; cat out9; exit 1; }
cmp -s "$1" "$T/first.so" || { echo "FAIL: the swapped object was not built again on 2 ranks"; exit 1; }
# the default tiers load cached objects too: a swapped one there is found the same way
cp "$2" "$1"
XDG_CACHE_HOME="$D" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit_tier_ms 0 > out7 2>&1 || { cat out7; exit 1; }
[ "$(grep "L2 error" out7)" = "$(grep "L2 error" out2)" ] || { echo "FAIL: a swapped object in the tiers"; cat out7; exit 1; }
# a run ended by SIGTERM while its background builds run: the compilers are ended and their
# outputs removed (a Ctrl-C left gcc's temporary object in the cache for good)
E="$T/sig"
cat > "$T/busy.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 16}
local P2 = lg.lagrange(2)
local u, v = lg.unknown(P2, "u"), lg.test(P2, "v")
for k = 1, 6 do -- six kernels for the background compiler
  lg.integrate(mesh, lg.sin(k*lg.x)*lg.cos(lg.y))
end
io.stderr:write("started\n")
local t0 = os.time()
while os.time() - t0 < 20 do end
LUA
XDG_CACHE_HOME="$E" "$BUILD/lugal" "$T/busy.lua" -lugal_jit_tier_ms 0 2> "$T/busy.err" &
pid=$!
n=0; while ! grep -q started "$T/busy.err" 2> /dev/null && [ $n -lt 100 ]; do sleep 0.1; n=$((n + 1)); done
kill -TERM $pid
wait $pid 2> /dev/null
left=$(find "$E" -name '*.tmp' 2> /dev/null | head -n 3)
[ -z "$left" ] || { echo "FAIL: SIGTERM during background builds left $left"; exit 1; }
# a folder that others can write to is not loaded from: libtcc's code, the same answer
chmod 777 "$C/lugal"
XDG_CACHE_HOME="$C" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out3 2>&1 || { cat out3; exit 1; }
grep -q "is not a private folder of this user.*kernels run libtcc's code instead" out3 || { cat out3; exit 1; }
[ "$(grep -c "kernels run libtcc" out3)" = 1 ] || { echo "FAIL: the fallback told more than once"; cat out3; exit 1; }
[ "$(grep "L2 error" out3)" = "$(grep "L2 error" out2)" ] || { echo "FAIL: the fallback's answer"; cat out3; exit 1; }
# an XDG_CACHE_HOME longer than a path can be is refused with its length, not cut short
chmod 700 "$C/lugal"
long=/$(head -c 5000 /dev/zero | tr '\0' a)
XDG_CACHE_HOME="$long" "$BUILD/lugal" "$ROOT/examples/poisson.lua" 8 -lugal_jit cc > out8 2>&1 || { cat out8; exit 1; }
grep -q "XDG_CACHE_HOME is 5001 bytes long" out8 || { echo "FAIL: a long XDG_CACHE_HOME"; cat out8; exit 1; }
echo "jit cache: ok"

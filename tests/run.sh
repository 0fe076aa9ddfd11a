#!/bin/sh
# tests/run.sh BUILD — runs every test: the C unit tests, the Lua script tests and every
# example; prints one line per test and ends with "N passed, N failed".
BUILD=${1:-build}
ROOT=$(pwd)
LUGAL=$ROOT/$BUILD/lugal
OUT=$ROOT/tests/out
mkdir -p "$OUT"
pass=0
fail=0
run() {
  name=$1
  shift
  log="$OUT/$(echo "$name" | tr / _).log"
  start=$(date +%s.%N)
  if "$@" > "$log" 2>&1; then
    pass=$((pass + 1))
    printf 'PASS %-32s %7.2fs\n' "$name" "$(awk "BEGIN { print $(date +%s.%N) - $start }")"
  else
    fail=$((fail + 1))
    printf 'FAIL %s (log: %s)\n' "$name" "${log#$ROOT/}"
    tail -n 15 "$log" | sed 's/^/    /'
  fi
}
for t in "$ROOT/$BUILD"/tests/*; do
  [ -x "$t" ] || continue
  run "c/$(basename "$t")" "$t" "$ROOT/tests/data"
done
for t in "$ROOT"/tests/lua/test_*.lua; do
  run "lua/$(basename "$t" .lua)" "$LUGAL" "$t"
done
for t in "$ROOT"/tests/sh/test_*.sh; do
  run "sh/$(basename "$t" .sh)" sh "$t" "$ROOT/$BUILD"
done
# examples run in a scratch folder so their output files stay out of the tree
mkdir -p "$OUT/examples"
for e in "$ROOT"/examples/*.lua; do
  name=$(basename "$e" .lua)
  run "example/$name" sh -c "cd '$OUT/examples' && '$LUGAL' '$e'"
done
# the standalone module in a plain Lua interpreter
# (a sanitized module needs the sanitizer runtimes preloaded into the plain interpreter)
if command -v lua5.4 > /dev/null 2>&1 && [ -f "$ROOT/$BUILD/lugal.so" ]; then
  preload=
  if nm -D "$ROOT/$BUILD/lugal.so" 2>/dev/null | grep -q __asan_init; then
    preload="$(gcc -print-file-name=libasan.so):$(gcc -print-file-name=libubsan.so)"
  fi
  run "module/poisson-lua5.4" sh -c "cd '$OUT/examples' && LD_PRELOAD='$preload' XDG_CACHE_HOME='$OUT/cache' lua5.4 -e \"package.cpath='$ROOT/$BUILD/?.so;'..package.cpath\" '$ROOT/examples/poisson.lua' 16 2"
fi
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]

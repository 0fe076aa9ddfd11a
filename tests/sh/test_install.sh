#!/bin/sh
# test_install.sh BUILD — make install into a scratch DESTDIR: the Lua module lands where a
# plain lua5.4 looks with the configured prefix (it went to lib/x86_64-linux-gnu/lua/5.4,
# which Debian's lua5.4 does not search under /usr/local), only the public headers are
# installed and each compiles on its own, the LICENSE comes along, and make uninstall
# removes every file install put there.
BUILD=$1
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
cd "$ROOT" || exit 1
make -s install DESTDIR="$T/d" > "$T/log" 2>&1 || { cat "$T/log"; fail "make install"; }
prefix=$(sed -n 's/^PREFIX *= *//p' Makefile)
[ -n "$prefix" ] || fail "no PREFIX in the Makefile"
mod="$T/d$prefix/lib/lua/5.4/lugal.so"
[ -f "$mod" ] || fail "the Lua module is not in $prefix/lib/lua/5.4"
if command -v lua5.4 > /dev/null 2>&1; then
  lua5.4 -e 'print(package.cpath)' | tr ';' '\n' | grep -qx "$prefix/lib/lua/5.4/?.so" ||
    echo "note: lua5.4 does not search $prefix/lib/lua/5.4 (a prefix other than Debian's /usr/local)"
fi
[ -f "$T/d$prefix/share/doc/lugal/LICENSE" ] || fail "no LICENSE installed"
inc="$T/d$prefix/include/lugal"
for h in problem/problem_int.h problem/solver.h kernel/vmath.h parallel/parallel_int.h optimize/optimize_int.h optimize/checkpoint.h; do [ ! -e "$inc/assemble/$h" ] || fail "internal header $h installed"; done
for h in untangle/untangle_int.h quality/quality_int.h tuplehash.h dense.h io/deflate.h; do [ ! -e "$inc/mesh/$h" ] || fail "internal header $h installed"; done
[ ! -e "$inc/expr/expr_int.h" ] || fail "internal header expr_int.h installed"
cflags=$(pkg-config --cflags PETSc 2> /dev/null || echo "-I/usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real/include")
for h in mesh/mesh.h mesh/io/io.h mesh/io/svg.h mesh/quality/quality.h mesh/untangle/untangle.h expr/expr.h assemble/assemble.h \
  assemble/fem/fem.h assemble/kernel/kernel.h assemble/process/process.h assemble/parallel/parallel.h assemble/problem/problem.h \
  assemble/optimize/optimize.h; do
  printf '#include <%s>\nint main(void) { return 0; }\n' "$h" > "$T/t.c"
  cc -std=c11 -fsyntax-only -I"$inc" $cflags "$T/t.c" 2> "$T/cc" || { cat "$T/cc"; fail "the installed $h does not compile on its own"; }
done
make -s uninstall DESTDIR="$T/d" > "$T/log" 2>&1 || { cat "$T/log"; fail "make uninstall"; }
left=$(find "$T/d" -type f | head -n 5)
[ -z "$left" ] || fail "make uninstall left: $left"
echo "install: module in $prefix/lib/lua/5.4, public headers only (each compiles), uninstall removes all"

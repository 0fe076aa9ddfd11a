#!/bin/sh
# test_launcher.sh BUILD — the `lugal` command (src/lua/launch.c) hands the run to
# lugal-core with glibc's huge-page tunable set only with -lugal_hugepages 1: added to the
# user's other tunables, never overriding a glibc.malloc.hugetlb the user chose; the
# core's exit status and arguments pass through; where the kernel offers transparent huge
# pages, a problem's large arrays land on them (AnonHugePages in /proc/self/smaps_rollup);
# the single-process MPI settings are made unless the user made them; GOMP_SPINCOUNT=1000
# unless the user chose a spin count or a waiting policy; 2000 arguments reach the script.
BUILD=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
printf 'print(os.getenv("GLIBC_TUNABLES") or "(unset)")\nprint(arg[1], arg[2], arg[3])\n' > "$T/env.lua"

out=$(env -u GLIBC_TUNABLES "$BUILD/lugal" "$T/env.lua" a b 2>&1) || fail "status $?: $out"
[ "$(echo "$out" | sed -n 1p)" = "(unset)" ] || fail "by default: got '$out'"
[ "$(echo "$out" | sed -n 2p)" = "a	b	nil" ] || fail "arguments: got '$(echo "$out" | sed -n 2p)'"

# many arguments: all in arg and in the script's "..." (over about 40 had written past the
# Lua stack, and the run crashed in MPI_Finalize)
printf 'local n = select("#", ...)\nprint(#arg, n, arg[2000], (select(n, ...)))\n' > "$T/many.lua"
out=$("$BUILD/lugal" "$T/many.lua" $(seq 1 2000) 2> "$T/many.err") || fail "2000 arguments: status $?: $out $(cat "$T/many.err")"
[ "$out" = "2000	2000	2000	2000" ] || fail "2000 arguments: got '$out'"

out=$(env -u GLIBC_TUNABLES "$BUILD/lugal" "$T/env.lua" -lugal_hugepages 1 2>&1)
[ "$(echo "$out" | sed -n 1p)" = "glibc.malloc.hugetlb=1" ] || fail "-lugal_hugepages 1: got '$out'"
echo "$out" | grep -q "was not used" && fail "-lugal_hugepages reported as unused: $out"

out=$(GLIBC_TUNABLES=glibc.malloc.arena_max=2 "$BUILD/lugal" "$T/env.lua" -lugal_hugepages 1 | sed -n 1p)
[ "$out" = "glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1" ] || fail "appended: got '$out'"
out=$(GLIBC_TUNABLES=glibc.malloc.arena_max=2 "$BUILD/lugal" "$T/env.lua" | sed -n 1p)
[ "$out" = "glibc.malloc.arena_max=2" ] || fail "the user's tunables by default: got '$out'"

out=$(GLIBC_TUNABLES=glibc.malloc.hugetlb=0 "$BUILD/lugal" "$T/env.lua" -lugal_hugepages 1 | sed -n 1p)
[ "$out" = "glibc.malloc.hugetlb=0" ] || fail "the user's choice: got '$out'"

out=$(env -u GLIBC_TUNABLES "$BUILD/lugal" "$T/env.lua" -lugal_hugepages 0 2>&1)
[ "$(echo "$out" | sed -n 1p)" = "(unset)" ] || fail "-lugal_hugepages 0: got '$out'"

# a single process sets Open MPI's and hwloc's in-process settings before PETSc starts
# (src/assemble/process/process.c), keeping the user's own
printf 'print(os.getenv("HWLOC_COMPONENTS"), os.getenv("OMPI_MCA_coll"))\n' > "$T/mpienv.lua"
out=$(env -u HWLOC_COMPONENTS -u OMPI_MCA_coll "$BUILD/lugal" "$T/mpienv.lua" 2>/dev/null)
[ "$out" = "-linuxio	basic,self,libnbc" ] || fail "single-process settings: got '$out'"
out=$(HWLOC_COMPONENTS=linux OMPI_MCA_coll=^hcoll "$BUILD/lugal" "$T/mpienv.lua" 2>/dev/null)
[ "$out" = "linux	^hcoll" ] || fail "the user's settings: got '$out'"

# libgomp's waiting threads spin briefly (GOMP_SPINCOUNT=1000) unless the user chose a spin
# count or a waiting policy
printf 'print(os.getenv("GOMP_SPINCOUNT") or "(unset)")\n' > "$T/spin.lua"
out=$(env -u GOMP_SPINCOUNT -u OMP_WAIT_POLICY "$BUILD/lugal" "$T/spin.lua" 2>/dev/null)
[ "$out" = "1000" ] || fail "GOMP_SPINCOUNT: got '$out'"
out=$(env -u OMP_WAIT_POLICY GOMP_SPINCOUNT=50 "$BUILD/lugal" "$T/spin.lua" 2>/dev/null)
[ "$out" = "50" ] || fail "the user's GOMP_SPINCOUNT: got '$out'"
out=$(env -u GOMP_SPINCOUNT OMP_WAIT_POLICY=active "$BUILD/lugal" "$T/spin.lua" 2>/dev/null)
[ "$out" = "(unset)" ] || fail "with the user's OMP_WAIT_POLICY: got '$out'"

printf 'error("boom")\n' > "$T/err.lua"
"$BUILD/lugal" "$T/err.lua" > /dev/null 2>&1
rc=$?
[ $rc = 1 ] || fail "a script error exits $rc, expected 1"

# a problem of 270 000 unknowns allocates arrays of tens of MB: on huge pages when asked
# and offered, not by default
cat > "$T/thp.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.box{nx = 48, ny = 48, nz = 48}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u))), test = v, unknown = u}
prob:assemble()
local f = io.open("/proc/self/smaps_rollup")
local kb = f and tonumber(f:read("a"):match("AnonHugePages:%s*(%d+)")) or -1
print(kb)
LUA
thp=$(cat /sys/kernel/mm/transparent_hugepage/enabled 2>/dev/null)
# a sanitized build's malloc is the sanitizer's, which glibc's tunables do not reach
if nm "$BUILD/lugal-core" 2>/dev/null | grep -q __asan_init; then thp="sanitized build"; fi
case "$thp" in
  *"[always]"*|*"[madvise]"*)
    kb=$("$BUILD/lugal" "$T/thp.lua" -lugal_hugepages 1) || fail "the huge-page run failed"
    [ "$kb" -ge 20480 ] || fail "AnonHugePages $kb kB with huge pages on, expected >= 20 MB"
    kb0=$("$BUILD/lugal" "$T/thp.lua")
    case "$thp" in *"[madvise]"*) [ "$kb0" -lt "$kb" ] || fail "AnonHugePages $kb0 kB by default, not below $kb";; esac
    echo "launcher: tunables passed; AnonHugePages $kb kB (off: $kb0 kB)" ;;
  *) echo "launcher: tunables passed; no huge-page check ($thp)" ;;
esac

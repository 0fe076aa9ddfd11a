#!/bin/sh
# test_time_memory.sh BUILD — a time-dependent gradient with 16 snapshots keeps memory flat
# (issue 55): the heat equation on 32² P1 at 5000 steps, peak resident memory (VmHWM) of the
# value and gradient within 10% of the plain march's (step:solve(); measured 1.03) and within
# 512 kB of the same at 500 steps; every state kept grows by the 4500 states (39 MB), which
# shows the measure sees growth. Each run its own process, one thread, kernels by libtcc
# alone and no huge pages (-lugal_hugepages 0): with them the figures move by their 2 MB
# grain, and the background compiler's timing moves them too. Under AddressSanitizer (its
# shadow and quarantine change the resident memory) the figures are printed, not checked.
BUILD=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
cat > "$T/heat.lua" <<'LUA'
local lg = require "lugal"
local steps, mode = tonumber(arg[1]), arg[2]
local mesh = lg.mesh.rectangle{nx = 32}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local x, y, pi = lg.x, lg.y, math.pi
local dt = 1 / steps
local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
local f = lg.control(P1, mesh, "f", 1 + x)
local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, dt = dt, t1 = 1, monitor = false,
                             eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + 0.1*lg.dot(lg.grad(u), lg.grad(v)) - f*v),
                             bc = lg.essential_bc(mesh:boundary(), v*u)}
if mode == "plain" then
  step:solve()
else
  local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - x*y)^2), running = lg.integral(mesh:cells(), 0.5*u^2)}
  local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = mode == "all" and "all" or 16}
  rf:gradient(1 + x)
  assert(mode == "all" or rf:stats().states == 18)
end
local s = io.open("/proc/self/status"):read("a")
print(tonumber(s:match("VmHWM:%s*(%d+)")))
LUA
run() { OMP_NUM_THREADS=1 "$BUILD/lugal" "$T/heat.lua" "$@" -lugal_jit tcc -lugal_hugepages 0 2> "$T/err" | tail -1 || fail "$* failed: $(cat "$T/err")"; }
plain=$(run 5000 plain)
ck=$(run 5000 16)
ck500=$(run 500 16)
all=$(run 5000 all)
all500=$(run 500 all)
for n in "$plain" "$ck" "$ck500" "$all" "$all500"; do
  case $n in '' | *[!0-9]*) fail "not a peak memory in kB: '$n' ($(cat "$T/err"))" ;; esac
done
echo "peak RSS (kB): plain march $plain, 16 snapshots $ck (500 steps: $ck500), every state $all (500 steps: $all500)"
if nm "$BUILD/lugal-core" 2> /dev/null | grep -q __asan_init; then
  echo "AddressSanitizer build: not checked"
  exit 0
fi
[ $((ck * 100)) -le $((plain * 110)) ] || fail "16 snapshots at 5000 steps: $ck kB, more than 1.1 x the plain march's $plain kB"
d=$((ck - ck500))
[ $d -le 512 ] && [ $d -ge -512 ] || fail "16 snapshots: $d kB more at 5000 steps than at 500"
[ $((all - all500)) -ge 30000 ] || fail "every state kept: only $((all - all500)) kB more at 5000 steps than at 500"
exit 0

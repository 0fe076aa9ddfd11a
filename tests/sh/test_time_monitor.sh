#!/bin/sh
# test_time_monitor.sh BUILD — the progress lines of time-dependent problems (issue 55):
# step:solve() prints one every `every` steps (step, t, dt, iterations, seconds); a reduced
# functional with monitor = true one per sweep as often (forward counting up to the last
# step, the adjoint down to step 1), step:sensitivity as the problem's own (tangent), none
# with monitor = false.
BUILD=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
cat > "$T/mon.lua" <<'LUA'
local lg = require "lugal"
local x = lg.x
local mesh = lg.mesh.rectangle{nx = 4}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local u0 = lg.interpolate(P1, mesh, x, "u0")
local f = lg.control(P1, mesh, "f", 1 + x)
local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, dt = 0.1, steps = 20, every = 5,
  monitor = arg[1] == "solve" or arg[1] == "sens", eqn = lg.integral(mesh:cells(), (u - u0)/0.1*v + lg.dot(lg.grad(u), lg.grad(v)) - f*v)}
if arg[1] == "solve" then step:solve() return end
if arg[1] == "sens" then step:sensitivity(f, x) return end
local rf = lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u^2)},
                                 control = f, monitor = arg[1] == "rf", checkpoints = 4}
rf:gradient(1 + x)
step:sensitivity(f, x)
LUA
out=$("$BUILD/lugal" "$T/mon.lua" solve 2>&1) || fail "solve: $out"
[ "$(echo "$out" | grep -c '^step [0-9]* of 20: t = [0-9.]*, dt = 0.1, [0-9]* linear iterations, [0-9.]* s$')" = 4 ] ||
  fail "step:solve's lines: $out"
out=$("$BUILD/lugal" "$T/mon.lua" rf 2>&1) || fail "rf: $out"
echo "$out" | grep -q '^forward: step 5 of 20 (t = 0.5), [0-9.]* s$' || fail "no forward line: $out"
[ "$(echo "$out" | grep -c '^forward: ')" = 4 ] || fail "forward lines: $out"
[ "$(echo "$out" | grep -c '^adjoint: ')" = 5 ] || fail "adjoint lines (20, 15, 10, 5, 1): $out"
echo "$out" | grep -q '^adjoint: step 1 of 20 (t = 0.1)' || fail "the adjoint's last line: $out"
out=$("$BUILD/lugal" "$T/mon.lua" sens 2>&1) || fail "sens: $out"
[ "$(echo "$out" | grep -c '^tangent: step [0-9]* of 20 (t = [0-9.]*), [0-9.]* s$')" = 4 ] || fail "tangent lines: $out"
out=$("$BUILD/lugal" "$T/mon.lua" quiet 2> "$T/err") || fail "quiet: $out $(cat "$T/err")"
[ -z "$out" ] || fail "monitor = false printed: $out" # (stdout only: a sanitizer's report goes to stderr)
exit 0

-- bench/time_adjoint.lua — the cost of a time-dependent gradient against its forward run
-- (issue 55): the heat equation by backward Euler on an N² P1 mesh, a source constant in time
-- (a control), J = 1/2 ∫ (u(T) - d)² + running 1/2 ∫∫ u². Prints the forward march (rf:value
-- after the control changed), the backward sweep (rf:gradient right after), their ratio, the
-- forward steps the sweep recomputed and the peak resident memory, for every state kept and
-- for s snapshots; with "plain" the march alone (step:solve()), for its time and memory.
-- "r+d" takes r snapshots in memory and d on disk (the multistage schedule; files in $TMPDIR).
--   lugal bench/time_adjoint.lua N steps [snapshots | r+d | plain]
local lg = require "lugal"
local N = tonumber(arg[1]) or 32
local steps = tonumber(arg[2]) or 100
local snaps = tonumber(arg[3]) -- "all" (or nothing): every state
local plain = arg[3] == "plain"
local ram, disk = (arg[3] or ""):match("^(%d+)%+(%d+)$")
if ram then snaps = {ram = tonumber(ram), disk = tonumber(disk)} end
local mesh = lg.mesh.rectangle{nx = N}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local x, y, pi = lg.x, lg.y, math.pi
local dt = 1 / steps
local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
local f = lg.control(P1, mesh, "f", 1 + x)
local d = lg.interpolate(P1, mesh, x*y, "d")
local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, dt = dt, t1 = 1, monitor = false,
                             eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + 0.1*lg.dot(lg.grad(u), lg.grad(v)) - f*v),
                             bc = lg.essential_bc(mesh:boundary(), v*u)}
local function hwm()
  local s = io.open("/proc/self/status"):read("a")
  return tonumber(s:match("VmHWM:%s*(%d+)")) / 1024
end
if plain then
  local t0 = lg.wtime()
  step:solve()
  print(string.format("time_adjoint N=%d steps=%d plain march (step:solve): %.3f s, peak RSS %.0f MB", N, steps,
                      lg.wtime() - t0, hwm()))
  return
end
local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - d)^2), running = lg.integral(mesh:cells(), 0.5*u^2)}
local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = snaps or "all"}
local function hwm()
  local s = io.open("/proc/self/status"):read("a")
  return tonumber(s:match("VmHWM:%s*(%d+)")) / 1024
end
local J1 = rf:value(1 + x)
rf:gradient() -- kernels compiled, solvers set up
local tf, tg = {}, {}
for r = 1, 3 do
  local t0 = lg.wtime()
  rf:value(1 + x + 0.01*r*y)
  local t1 = lg.wtime()
  rf:gradient()
  local t2 = lg.wtime()
  tf[r], tg[r] = t1 - t0, t2 - t1
end
table.sort(tf)
table.sort(tg)
local st = rf:stats()
print(string.format("time_adjoint N=%d steps=%d checkpoints=%s: forward %.3f s, gradient sweep %.3f s (%.2f x the forward), "
                    .. "%d steps recomputed, %d states held (%d in memory, %d files written, %d read), peak RSS %.0f MB, J %.12e",
                    N, steps, ram and arg[3] or snaps and tostring(snaps) or "all", tf[2], tg[2], tg[2] / tf[2], st.recomputed,
                    st.states, st.in_memory, st.disk_writes, st.disk_reads, hwm(), J1))

-- mpi_time_cases.lua — time-dependent reduced functionals (lg.time_problem) whose values and
-- gradients a parallel run must give as the serial run does: tests/lua/mpi_cases.lua (whole
-- meshes) and mpi_dist.lua (distributed meshes) call it with their `out` (name, tolerance
-- class, value). Not a test of its own.
return function(lg, out)
local x, y, pi = lg.x, lg.y, math.pi
local function sum(t) local s = 0 for _, v in ipairs(t) do s = s + v end return s end
-- a time-dependent reduced functional (lg.time_problem): the heat equation by backward Euler
-- with a diffusivity rising in time; a source, a parameter and the initial state as controls;
-- final, running and observed terms; gradients with every state kept and with 3 snapshots
do
  local mesh = lg.mesh.rectangle{nx = 12}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local t, kappa = lg.parameter("t", 0), lg.parameter("kappa", 0.4)
  local u0 = lg.control(P1, mesh, "u0", lg.sin(pi*x)*lg.sin(pi*y))
  local f = lg.control(P1, mesh, "f", 1 + x)
  local d = lg.interpolate(P1, mesh, x*y, "d")
  local dt = 0.05
  local F = lg.integral(mesh:cells(), (u - u0)/dt*v + kappa*(1 + t)*lg.dot(lg.grad(u), lg.grad(v)) - f*(1 + t)*v)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, t1 = 0.5, time = t,
                               bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
  local uT = step:solve()
  out("time_uT_sum", "direct", sum(uT:values()))
  local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - d)^2), running = lg.integral(mesh:cells(), 0.5*u^2),
                          at = {[0.25] = lg.integral(mesh:cells(), u*x)}}
  for _, ck in ipairs{"all", 3, {ram = 1, disk = 2}} do
    local rf = lg.reduced_functional{problem = step, functional = J, control = {f, kappa, u0}, checkpoints = ck}
    if type(ck) == "table" then ck = "disk" end -- each rank its own folder of files
    out("time_J_" .. ck, "direct", rf:value())
    local gf, gk, gu = rf:gradient(nil, {riesz = "none"})
    local a, b = gf:values(), gu:values()
    local s1, s2 = 0, 0
    for i = 1, #a do s1 = s1 + a[i]*(1 + i % 7) end
    for i = 1, #b do s2 = s2 + b[i]*(1 + i % 5) end
    out("time_grad_f_" .. ck, "direct", s1)
    out("time_grad_kappa_" .. ck, "direct", gk)
    out("time_grad_u0_" .. ck, "direct", s2)
    out("time_recomputed_" .. ck, "count", rf:stats().recomputed)
  end
end

-- the tangent march (step:sensitivity) and an adaptive march on the ranks: the ranks agree on
-- each step's size (the least they choose), so the steps and the state are the serial run's
do
  local mesh = lg.mesh.rectangle{nx = 10}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local t, h, kappa = lg.parameter("t", 0), lg.parameter("h", 0.1), lg.parameter("kappa", 0.3)
  local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local F = lg.integral(mesh:cells(), (u - u0)/h*v + kappa*(1 + u^2)*lg.dot(lg.grad(u), lg.grad(v)) - (1 + t)*v)
  local bc = lg.essential_bc(mesh:boundary(), v*u)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.1, steps = 4, time = t,
                               step_size = h, nonlinear = true, bc = bc, monitor = false}
  out("time_sens_kappa", "direct", sum(step:sensitivity(kappa):values()))
  local ad = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, t1 = 0.4, time = t, step_size = h,
                             nonlinear = true, bc = bc, monitor = false,
                             dt = function(k, tk, last) return last and math.min(2*last.dt, 0.15) or 0.02 end}
  local uA, info = ad:solve()
  out("time_adaptive_steps", "count", info.steps)
  out("time_adaptive_sum", "direct", sum(uA:values()))
end

-- a control per step time (and its companion) on the ranks: the gradient's blocks as the serial run's
do
  local mesh = lg.mesh.rectangle{nx = 10}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local t = lg.parameter("t", 0)
  local u0 = lg.interpolate(P1, mesh, 0*x, "u0")
  local f, fp = lg.control(P1, mesh, "f", 0*x, {per_step = true})
  local dt = 0.1
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, dt = dt, t1 = 0.6, time = t, monitor = false,
                               eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + 0.1*lg.dot(lg.grad(u), lg.grad(v)) - 0.5*(f + fp)*v),
                               bc = lg.essential_bc(mesh:boundary(), v*u)}
  local J = lg.functional{running = lg.integral(mesh:cells(), 0.5*(u - x*y*t)^2 + 0.01*((f - fp)/dt)^2)}
  local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = 3}
  out("time_ps_J", "direct", rf:value(lg.sin(3*t)*x))
  local g = rf:gradient(nil, {riesz = "l2"})
  local s = 0
  for k, gk in ipairs(g) do
    local vals = gk:values()
    for i = 1, #vals do s = s + vals[i]*(k + i % 3) end
  end
  out("time_ps_grad", "direct", s)
end
end

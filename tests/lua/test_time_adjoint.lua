-- Time-dependent problems and their adjoints (src/assemble/problem/time.c,
-- src/assemble/optimize/time_adjoint.c): step:solve() must march as a hand-written loop of
-- steady solves does, to the bit, and leave the initial state as it was; gradients of
-- reduced functionals over the march must pass Taylor tests (rate 2.00 +- 0.05) for linear
-- and nonlinear steps, backward Euler, Crank-Nicolson and BDF2, a matrix that changes with
-- time, field, parameter, initial-state and Dirichlet controls, final, running and observed
-- terms; every checkpoint schedule must give the same gradient (1e-12), and the binomial
-- schedule must recompute exactly Griewank and Walther's minimal number of forward steps.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local pi = math.pi
local x, y = lg.x, lg.y

local mesh = lg.mesh.rectangle{nx = 6, ny = 6}
local P1 = lg.lagrange(1)
local v, u = lg.test(P1, "v"), lg.unknown(P1, "u")

local function rate_ok(t, what)
  local r = t.rates1[#t.rates1]
  T.check(math.abs(r - 2) < 0.05, "%s: Taylor rate %.3f (want 2.00 +- 0.05)\n%s", what, r, tostring(t))
  return r
end

-- Griewank and Walther: t(l, s) = r l - C(s + r, s + 1), r the least with C(s + r, s) >= l
local function binom(n, k)
  local c = 1
  for i = 1, k do c = c * (n - k + i) / i end
  return c
end
local function revolve(l, s)
  if l <= 1 then return 0 end
  local r = 0
  while binom(s + r, s) < l do r = r + 1 end
  return math.floor(r * l - binom(s + r, s + 1) + 0.5)
end

-- checkpoint files: a folder of this run's, the names in a folder, a schedule's name
local ckdir = os.tmpname()
os.remove(ckdir)
local function files(dir)
  local out, p = {}, io.popen('ls -A "' .. dir .. '" 2>/dev/null')
  for l in p:lines() do out[#out + 1] = l end
  p:close()
  return out
end
local function ckname(ck)
  if type(ck) ~= "table" then return tostring(ck) end
  return string.format("{ram = %d, disk = %d}", ck.ram, ck.disk)
end
local lastrec

-- 1. step:solve() against a hand-written loop of linear solves (the same bits), the initial
-- state left as it was, the time parameter too
do
  local t = lg.parameter("t", -1)
  local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local dt = 0.1
  local F = lg.integral(mesh:cells(), (u - u0)/dt*v + 0.3*lg.dot(lg.grad(u), lg.grad(v)) - (1 + t)*x*v)
  local bc = lg.essential_bc(mesh:boundary(), v*u)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, bc = bc, dt = dt, t1 = 0.5,
                               time = t, monitor = false}
  local before = u0:values()
  local uT, info = step:solve()
  T.check(info.steps == 5, "steps %d", info.steps)
  local after = u0:values()
  for i = 1, #before do T.check(before[i] == after[i], "step:solve() changed the initial state at dof %d", i) end
  T.check(t:value() == -1, "the time parameter was not restored (%g)", t:value())
  local w = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "w")
  local Fw = lg.integral(mesh:cells(), (u - w)/dt*v + 0.3*lg.dot(lg.grad(u), lg.grad(v)) - (1 + t)*x*v)
  local prob = lg.linear_problem{mesh = mesh, eqn = Fw, bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  for k = 1, 5 do
    t:set(k*dt)
    w:assign((prob:solve()))
  end
  local a, b = uT:values(), w:values()
  for i = 1, #a do T.check(a[i] == b[i], "step:solve() differs from the loop at dof %d: %.17g %.17g", i, a[i], b[i]) end
  local times = step:times()
  T.close(times[#times], 0.5, 1e-15, "the last step's time")
  print(string.format("time_problem: 5 steps equal to a loop of solves to the bit, u0 and t kept"))
end

-- 2. the heat equation by backward Euler and by Crank-Nicolson (the step reads grad u0),
-- diffusivity rising in time (a new matrix every step), a source f, a parameter kappa and
-- the initial state as controls, final + running + observed terms; every schedule
do
  local t = lg.parameter("t", 0)
  local kappa = lg.parameter("kappa", 0.4)
  local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local f = lg.control(P1, mesh, "f", 1 + x)
  local d = lg.interpolate(P1, mesh, x*y, "d")
  local dt = 0.05
  for _, scheme in ipairs{"backward Euler", "Crank-Nicolson"} do
    local th = scheme == "backward Euler" and 1 or 0.5
    local A = function(w) return kappa*(1 + t)*lg.dot(lg.grad(w), lg.grad(v)) end
    local F = lg.integral(mesh:cells(), (u - u0)/dt*v + th*A(u) + (1 - th)*A(u0) - f*(1 + t)*v)
    local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, t1 = 0.5, time = t,
                                 bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
    local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - d)^2), running = lg.integral(mesh:cells(), 0.5*u^2),
                            at = {[0.25] = lg.integral(mesh:cells(), u*x)}}
    local grads = {}
    for _, ck in ipairs{"all", 4, 2, 1, {ram = 2, disk = 2, dir = ckdir}, {ram = 1, disk = 3}} do
      local rf = lg.reduced_functional{problem = step, functional = J, control = {f, kappa, u0}, checkpoints = ck}
      local tt = lg.taylor_test(rf, {1 + x, 0.4, lg.sin(pi*x)*lg.sin(pi*y)}, {x*y, 0.3, x*(1 - x)*y*(1 - y)}, {h = 0.05, steps = 4})
      local r = rate_ok(tt, scheme .. ", checkpoints " .. ckname(ck))
      local disk = type(ck) == "table"
      if disk then -- the value's march leaves the outer snapshots on disk; the gradient spends them
        rf:value({1 + x, 0.4, lg.sin(pi*x)*lg.sin(pi*y)})
        T.check(#files(rf:stats().dir) == ck.disk, "%d checkpoint files after the value's march (want %d)", #files(rf:stats().dir), ck.disk)
      end
      local gf, gk, gu = rf:gradient({1 + x, 0.4, lg.sin(pi*x)*lg.sin(pi*y)}, {riesz = "none"})
      grads[#grads + 1] = {gf:values(), gk, gu:values(), ckname(ck)}
      lastrec = rf:stats().recomputed
      if disk then
        local st = rf:stats()
        T.check(#files(st.dir) == 0, "checkpoint files left after the gradient: %d", #files(st.dir))
        T.check(st.disk_reads > 0 and st.disk_writes >= ck.disk, "disk snapshots written %d, read %d", st.disk_writes, st.disk_reads)
        T.check(st.in_memory == ck.ram + 2 and st.states == ck.ram + ck.disk + 2, "states %d, in memory %d", st.states, st.in_memory)
        if ck.dir then T.check(st.dir:sub(1, #ckdir + 1) == ckdir .. "/", "the private directory %s is not under %s", st.dir, ckdir) end
        local dir = st.dir
        rf = nil
        collectgarbage()
        collectgarbage()
        T.check(not os.rename(dir, dir), "the private checkpoint directory %s outlived its reduced functional", dir)
        print(string.format("time adjoint: %s, %d snapshots in memory and %d on disk: %d files written, %d read, all removed",
                            scheme, ck.ram, ck.disk, st.disk_writes, st.disk_reads))
      end
      if rf == nil then
        local st_ck = ck.ram + ck.disk
        T.check(lastrec == revolve(10, st_ck) - 10 + 1, "%s, %s: %d recomputed, the minimum is %d", scheme, ckname(ck), lastrec,
                revolve(10, st_ck) - 10 + 1)
      elseif ck ~= "all" then
        local want = revolve(10, ck) - 10 + 1
        T.check(rf:stats().recomputed == want, "%s, %d snapshots: %d forward steps recomputed, the minimum is %d", scheme, ck,
                rf:stats().recomputed, want)
      else T.check(rf:stats().recomputed == 0, "every state kept: nothing to recompute") end
      print(string.format("time adjoint: %s, checkpoints %-3s Taylor rate %.3f, %d steps recomputed", scheme, ckname(ck), r, lastrec))
    end
    for k = 2, #grads do
      local a, b = grads[1], grads[k]
      for i = 1, #a[1] do T.close(b[1][i], a[1][i], 1e-12, scheme .. " gradient (f) with checkpoints " .. b[4]) end
      T.close(b[2], a[2], 1e-12, scheme .. " gradient (kappa) with checkpoints " .. b[4])
      for i = 1, #a[3] do T.close(b[3][i], a[3][i], 1e-12, scheme .. " gradient (u0) with checkpoints " .. b[4]) end
    end
  end
end

local function hess_ok(t, what)
  local r = t.rates2[#t.rates2]
  T.check(math.abs(r - 3) < 0.1, "%s: second-order Taylor rate %.3f (want 3.0 +- 0.1)\n%s", what, r, tostring(t))
  T.check(math.abs(t.rates1[#t.rates1] - 2) < 0.05, "%s: first-order rate\n%s", what, tostring(t))
  return r
end

-- 3. a nonlinear step (u_t - div((1 + u^2) grad u) + u^3 = f), BDF2 (two previous states,
-- both controls), a Dirichlet control (the boundary value a)
do
  local a = lg.parameter("a", 0.2)
  local u0 = lg.interpolate(P1, mesh, 0.2 + x*y, "u0")
  local u00 = lg.interpolate(P1, mesh, 0.2 + 0.9*x*y, "u00")
  local f = lg.control(P1, mesh, "g", 1 - y)
  local dt = 0.1
  local F = lg.integral(mesh:cells(), (1.5*u - 2*u0 + 0.5*u00)/dt*v + (1 + u^2)*lg.dot(lg.grad(u), lg.grad(v)) + u^3*v - f*v)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = {u0, u00}, eqn = F, dt = dt, steps = 6,
                               bc = lg.essential_bc(mesh:boundary(), v*(u - a)), nonlinear = true, monitor = false}
  local _, info = step:solve()
  T.check(info.iterations >= 12, "Newton iterations %d over 6 steps", info.iterations)
  local J = lg.functional{final = lg.integral(mesh:cells(), u^2*x), running = lg.integral(mesh:cells(), 0.1*u^2)}
  local g1
  for _, ck in ipairs{"all", 3} do
    local rf = lg.reduced_functional{problem = step, functional = J, control = {f, a, u0, u00}, checkpoints = ck}
    local tt = lg.taylor_test(rf, {1 - y, 0.2, 0.2 + x*y, 0.2 + 0.9*x*y}, {x, 0.1, x*y*(1 - x), y*(1 - y)},
                              {h = 0.05, steps = 4, hessian = true})
    local r = rate_ok(tt, "nonlinear BDF2, checkpoints " .. tostring(ck))
    local r2 = hess_ok(tt, "nonlinear BDF2 Hessian with a Dirichlet control, checkpoints " .. tostring(ck))
    local gf, ga, g0, g00 = rf:gradient({1 - y, 0.2, 0.2 + x*y, 0.2 + 0.9*x*y}, {riesz = "none"})
    if not g1 then g1 = {ga, g0:values()} else
      T.close(ga, g1[1], 1e-12, "the Dirichlet gradient with 3 snapshots")
      local b = g0:values()
      for i = 1, #b do T.close(b[i], g1[2][i], 1e-12, "the initial state's gradient with 3 snapshots") end
      T.check(rf:stats().recomputed == revolve(6, 3) - 6 + 1, "recomputed %d", rf:stats().recomputed)
    end
    print(string.format("time adjoint: nonlinear BDF2 with a Dirichlet control, checkpoints %-3s Taylor rates %.3f, %.3f (Hessian)",
                        tostring(ck), r, r2))
  end
end

-- 3b. Hessian actions: a tangent march and a second-order backward sweep (rate 3.0 +- 0.1),
-- a nonlinear Crank-Nicolson step with a parameter in time-dependent diffusion, a field and
-- the initial state; BDF2 with a control per step and its companion in the step and a rate
-- term, both initial levels, an initial term; every state kept and 2 or 3 snapshots alike
do
  local t = lg.parameter("t", 0)
  local kappa = lg.parameter("kappa", 0.4)
  local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local f = lg.control(P1, mesh, "f", 1 + x)
  local d = lg.interpolate(P1, mesh, x*y, "d")
  local dt = 0.05
  local A = function(w) return kappa*(1 + t)*lg.dot(lg.grad(w), lg.grad(v)) end
  local F = lg.integral(mesh:cells(), (u - u0)/dt*v + 0.5*A(u) + 0.5*A(u0) + u^3*v - f*(1 + t)*v)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, t1 = 0.3, time = t,
                               nonlinear = true, bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
  local J = lg.functional{final = lg.integral(mesh:cells(), 0.5*(u - d)^2*(1 + f^2)), running = lg.integral(mesh:cells(), 0.5*u^2*kappa)}
  local q
  for _, ck in ipairs{"all", 3, {ram = 1, disk = 2}} do
    local rf = lg.reduced_functional{problem = step, functional = J, control = {f, kappa, u0}, checkpoints = ck}
    local tt = lg.taylor_test(rf, {1 + x, 0.4, lg.sin(pi*x)*lg.sin(pi*y)}, {x*y, 0.3, x*(1 - x)*y*(1 - y)},
                              {h = 0.1, steps = 4, hessian = true})
    local r = hess_ok(tt, "nonlinear Crank-Nicolson Hessian, checkpoints " .. ckname(ck))
    local hf, hk, hu = rf:hessian({x*y, 0.3, x*(1 - x)*y*(1 - y)}, nil, {riesz = "none"})
    local s = hk
    for _, val in ipairs(hf:values()) do s = s + val end
    for _, val in ipairs(hu:values()) do s = s + 2*val end
    if not q then q = s else T.close(s, q, 1e-12, "the Hessian action with checkpoints " .. ckname(ck)) end
    if type(ck) == "table" then T.check(rf:stats().disk_reads > 0, "the Hessian's sweeps read no disk snapshot") end
    print(string.format("time Hessian: nonlinear Crank-Nicolson, checkpoints %-3s second-order rate %.3f", ckname(ck), r))
  end
  -- and a symmetric one: a.H b = b.H a
  local rf = lg.reduced_functional{problem = step, functional = J, control = {f, kappa, u0}}
  local da, db = {x*y, 0.3, x*(1 - x)*y}, {lg.cos(x), -0.2, y*(1 - y)*x}
  local ha = {rf:hessian(da, {1 + x, 0.4, lg.sin(pi*x)*lg.sin(pi*y)}, {riesz = "none"})}
  local hb = {rf:hessian(db, nil, {riesz = "none"})}
  local function pair(h, dir)
    local s = h[2]*dir[2]
    for i, w in ipairs({1, 3}) do
      local vals = h[w]:values()
      local dv = lg.interpolate(P1, mesh, dir[w], "dv"):values()
      for k = 1, #vals do s = s + vals[k]*dv[k] end
    end
    return s
  end
  T.close(pair(ha, db), pair(hb, da), 1e-10, "the Hessian's symmetry")
end
do
  local t = lg.parameter("t", 0)
  local u0 = lg.interpolate(P1, mesh, 0.2 + x*y, "u0")
  local u00 = lg.interpolate(P1, mesh, 0.2 + 0.9*x*y, "u00")
  local f, fp = lg.control(P1, mesh, "g", 0*x, {per_step = true})
  local dt = 0.1
  local F = lg.integral(mesh:cells(), (1.5*u - 2*u0 + 0.5*u00)/dt*v + (1 + u^2)*lg.dot(lg.grad(u), lg.grad(v)) - 0.5*(f + fp)*u*v)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = {u0, u00}, eqn = F, dt = dt, steps = 5, time = t,
                               nonlinear = true, bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
  local J = lg.functional{final = lg.integral(mesh:cells(), u^2*x), running = lg.integral(mesh:cells(), 0.1*u^2 + ((f - fp)/dt)^2*0.01),
                          initial = lg.integral(mesh:cells(), u0^2*u00)}
  for _, ck in ipairs{"all", 2} do
    local rf = lg.reduced_functional{problem = step, functional = J, control = {f, u0, u00}, checkpoints = ck}
    local tt = lg.taylor_test(rf, {lg.sin(pi*t)*x, 0.2 + x*y, 0.2 + 0.9*x*y}, {lg.cos(2*t)*y, x*y*(1 - x), y*(1 - y)},
                              {h = 0.1, steps = 4, hessian = true})
    local r = hess_ok(tt, "BDF2 with a per-step control, checkpoints " .. tostring(ck))
    print(string.format("time Hessian: BDF2, a control per step, both initial levels, checkpoints %-3s second-order rate %.3f", tostring(ck), r))
  end
end

-- 3c. a boundary value per step time (a Dirichlet control per step) in a nonlinear step:
-- gradient and Hessian, every state kept and disk snapshots; its sensitivity
do
  local t = lg.parameter("t", 0)
  local u0 = lg.interpolate(P1, mesh, x*y, "u0")
  local g = lg.control(P1, mesh, "gb", 0*x, {per_step = true})
  local d = lg.interpolate(P1, mesh, lg.sin(pi*x)*y, "d")
  local dt = 0.1
  local F = lg.integral(mesh:cells(), (u - u0)/dt*v + (1 + u^2)*lg.dot(lg.grad(u), lg.grad(v)))
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, steps = 5, time = t,
                               nonlinear = true, bc = lg.essential_bc(mesh:boundary(), v*(u - g)), monitor = false}
  local J = lg.functional{final = lg.integral(mesh:cells(), (u - d)^2), running = lg.integral(mesh:cells(), 0.5*u^2)}
  local h1
  for _, ck in ipairs{"all", {ram = 1, disk = 1}} do
    local rf = lg.reduced_functional{problem = step, functional = J, control = g, checkpoints = ck}
    local tt = lg.taylor_test(rf, lg.sin(pi*t)*x, lg.cos(2*t)*(y + x), {h = 0.1, steps = 4, hessian = true})
    local r = hess_ok(tt, "a boundary value per step, checkpoints " .. ckname(ck))
    local hs = rf:hessian(lg.cos(2*t)*(y + x), lg.sin(pi*t)*x, {riesz = "none"})
    local sum = 0
    for k = 1, #hs do for _, w in ipairs(hs[k]:values()) do sum = sum + w end end
    if not h1 then h1 = sum else T.close(sum, h1, 1e-12, "the Hessian action with disk snapshots") end
    print(string.format("time Hessian: a boundary value per step (nonlinear), checkpoints %-3s second-order rate %.3f", ckname(ck), r))
  end
end

-- 4. the binomial schedule recomputes the minimum for several lengths and snapshot counts
do
  local u0 = lg.interpolate(P1, mesh, x, "u0")
  local m = lg.parameter("m", 1)
  local F = lg.integral(mesh:cells(), (u - u0)*v + 0.01*lg.dot(lg.grad(u), lg.grad(v)) - m*v)
  for _, c in ipairs{{7, 1}, {12, 2}, {16, 3}, {20, 4}, {33, 5}, {40, 40}} do
    local l, s = c[1], c[2]
    local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 1, steps = l, monitor = false}
    local rf = lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u^2)},
                                     control = m, checkpoints = s}
    local ga = rf:gradient(1)
    local rf2 = lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u^2)},
                                      control = m, checkpoints = "all"}
    T.close(ga, rf2:gradient(1), 1e-12, string.format("%d steps, %d snapshots: gradient", l, s))
    local want = math.max(0, revolve(l, s) - l + 1)
    T.check(rf:stats().recomputed == want, "%d steps, %d snapshots: %d recomputed, the minimum is %d", l, s, rf:stats().recomputed, want)
    print(string.format("revolve: %2d steps, %2d snapshots: %3d forward steps recomputed (t(l, s) - l + 1 = %d)", l, s,
                        rf:stats().recomputed, want))
  end
end

-- 4b. a control per step (lg.control's per_step): a Crank-Nicolson step whose source is the
-- mean of the values at the step's two times (the companion holds the one before), a rate
-- regularization; Taylor rates, every schedule alike, a table of one value per step time
do
  local t = lg.parameter("t", 0)
  local u0 = lg.interpolate(P1, mesh, 0*x, "u0")
  local f, fp = lg.control(P1, mesh, "f", 0*x, {per_step = true})
  T.check(fp ~= nil and fp:ndof() == f:ndof(), "lg.control with per_step returns the companion")
  local dt = 0.1
  local A = function(w) return 0.2*lg.dot(lg.grad(w), lg.grad(v)) end
  local F = lg.integral(mesh:cells(), (u - u0)/dt*v + 0.5*(A(u) + A(u0)) - 0.5*(f + fp)*v)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, t1 = 0.8, time = t,
                               bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
  local d = 16*x*(1 - x)*y*(1 - y)*lg.sin(pi*t)
  local J = lg.functional{running = lg.integral(mesh:cells(), 0.5*(u - d)^2 + 0.01/2*((f - fp)/dt)^2),
                          final = lg.integral(mesh:cells(), f^2)}
  local ref
  for _, ck in ipairs{"all", 3} do
    local rf = lg.reduced_functional{problem = step, functional = J, control = f, checkpoints = ck}
    local tt = lg.taylor_test(rf, lg.sin(pi*t)*x, lg.cos(3*t)*y, {h = 0.1, steps = 4})
    local r = rate_ok(tt, "a control per step, checkpoints " .. tostring(ck))
    local g = rf:gradient(lg.sin(pi*t)*x, {riesz = "none"})
    T.check(#g == 9, "the gradient of a per-step control: %d functions for 9 step times", #g)
    if not ref then ref = g else
      for k = 1, 9 do
        local a, b = ref[k]:values(), g[k]:values()
        for i = 1, #a do T.close(b[i], a[i], 1e-12, string.format("per-step gradient, time %d, 3 snapshots", k)) end
      end
    end
    print(string.format("time adjoint: a control per step (Crank-Nicolson, its value before), checkpoints %-3s Taylor rate %.3f", tostring(ck), r))
  end
  -- one value per step time as a table: the same as the expression of t
  local rf = lg.reduced_functional{problem = step, functional = J, control = f}
  local vals = {}
  for k = 0, 8 do vals[k + 1] = math.sin(pi*k*dt)*x end
  T.close(rf:value(vals), rf:value(lg.sin(pi*t)*x), 1e-14, "per-step values from a table and from an expression of t")
  T.fails(function() rf:value({x, y}) end, "one value or 9")
  T.fails(function() lg.reduced_functional{problem = lg.linear_problem{mesh = mesh, test = v, unknown = u,
            eqn = lg.integral(mesh:cells(), u*v - f*v)}, functional = lg.functional(lg.integral(mesh:cells(), u^2)), control = f} end,
          "value per step", "time-dependent problem")
  local fopt, info = lg.minimize(rf, {method = "lmvm", gttol = 1e-6, gatol = 0, grtol = 0, maxit = 400, monitor = false})
  T.check(#fopt == 9 and info.J < 0.5 * rf:value(0*x), "the minimizer of a per-step control: %d values, J %g", #fopt, info.J)
end

-- 4c. before_step(k, t): the script's function before each step (here it sets a source
-- function); replayed steps call it again; the same J and gradient as the time parameter's
-- expression; an error in it stops the march with its message
do
  local t = lg.parameter("t", 0)
  local u0 = lg.interpolate(P1, mesh, x*y, "u0")
  local s = lg.interpolate(P1, mesh, 0*x, "s")
  local f = lg.control(P1, mesh, "f", 1 + x)
  local dt, calls = 0.1, 0
  local function mk(src, hook)
    return lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, dt = dt, steps = 6, time = t, monitor = false,
      eqn = lg.integral(mesh:cells(), (u - u0)/dt*v + lg.dot(lg.grad(u), lg.grad(v)) - (f + src)*v),
      bc = lg.essential_bc(mesh:boundary(), v*u), before_step = hook}
  end
  local a = mk(s, function(k, tk) calls = calls + 1; s:assign(tk*(x + 2*y)) end)
  local b = mk(t*(x + 2*y))
  local J = lg.functional{final = lg.integral(mesh:cells(), u^2), running = lg.integral(mesh:cells(), u*x)}
  local ra = lg.reduced_functional{problem = a, functional = J, control = f, checkpoints = 2}
  local rb = lg.reduced_functional{problem = b, functional = J, control = f}
  T.close(ra:value(), rb:value(), 1e-13, "J with before_step")
  T.check(calls == 6, "before_step called %d times by the march", calls)
  local ga, gb = ra:gradient(nil, {riesz = "none"}):values(), rb:gradient(nil, {riesz = "none"}):values()
  for i = 1, #ga do T.close(ga[i], gb[i], 1e-12, "the gradient with before_step") end
  T.check(calls > 6, "the replayed steps call before_step again")
  local bad = mk(s, function(k) if k == 3 then error("no data for this step") end end)
  T.fails(function() bad:solve() end, "step:solve", "before_step(3,", "no data for this step")
  T.fails(function() mk(s, 1) end, "option 'before_step' must be a function")
  print(string.format("time_problem: before_step, %d calls (the march's 6, then the replays'), the same gradient", calls))
end

-- 4b. step:sensitivity: the tangent-linear march against central differences of step:solve()
-- (nonlinear steps, a parameter in time-dependent diffusion; a field and the initial state at
-- once, every step's tangent)
do
  local t = lg.parameter("t", 0)
  local kappa = lg.parameter("kappa", 0.4)
  local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local f = lg.control(P1, mesh, "f", 1 + x)
  local dt = 0.05
  local F = lg.integral(mesh:cells(), (u - u0)/dt*v + kappa*(1 + t)*(1 + u^2)*lg.dot(lg.grad(u), lg.grad(v)) - f*(1 + t)*v)
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, t1 = 0.5, time = t,
                               nonlinear = true, bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
  local h = 1e-5
  local function diff(a, p, m)
    local e, n = 0, 0
    for i = 1, #a do
      e = math.max(e, math.abs(a[i] - (p[i] - m[i])/(2*h)))
      n = math.max(n, math.abs(a[i]))
    end
    return e, n
  end
  local du = step:sensitivity(kappa)
  kappa:set(0.4 + h)
  local up = step:solve()
  kappa:set(0.4 - h)
  local um = step:solve()
  kappa:set(0.4)
  local e, n = diff(du:values(), up:values(), um:values())
  T.check(n > 0.1 and e < 1e-8*n, "du(t1)/dkappa against central differences: %.3g (max %.3g)", e, n)
  local hist = step:sensitivity({f, u0}, {x*y, x*(1 - x)}, {history = true})
  T.check(#hist == 11, "history of %d tangents (want 11)", #hist)
  local dx0, d0 = hist[1]:values(), lg.interpolate(P1, mesh, x*(1 - x), "d0"):values()
  for i = 1, #d0 do T.check(dx0[i] == d0[i], "the tangent at t0 is the initial state's direction (dof %d)", i) end
  local fv, u0v = f:values(), u0:values()
  local df, d0v = lg.interpolate(P1, mesh, x*y, "df"):values(), d0
  local function shift(sg)
    local a, b = {}, {}
    for i = 1, #fv do a[i], b[i] = fv[i] + sg*h*df[i], u0v[i] + sg*h*d0v[i] end
    f:assign(a)
    u0:assign(b)
  end
  local worst = 0
  for _, k in ipairs{1, 5, 10} do
    local s2 = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, steps = k, time = t,
                               nonlinear = true, bc = lg.essential_bc(mesh:boundary(), v*u), monitor = false}
    shift(1)
    local p = s2:solve()
    shift(-1)
    local m = s2:solve()
    shift(0)
    local e2, n2 = diff(hist[k + 1]:values(), p:values(), m:values())
    T.check(n2 > 0.01 and e2 < 1e-7*n2, "step %d's tangent along (f, u0) against central differences: %.3g (max %.3g)", k, e2, n2)
    worst = math.max(worst, e2/n2)
  end
  T.fails(function() step:sensitivity(f) end, "step:sensitivity", "direction")
  T.fails(function() step:sensitivity(kappa, 1, {histroy = true}) end, "histroy")
  local a = lg.parameter("a", 0)
  local sd = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = dt, steps = 2, time = t,
                             nonlinear = true, bc = lg.essential_bc(mesh:boundary(), v*(u - a)), monitor = false}
  local dua = sd:sensitivity(a)
  a:set(h)
  local pa = sd:solve()
  a:set(-h)
  local ma = sd:solve()
  a:set(0)
  local ea, na = diff(dua:values(), pa:values(), ma:values())
  T.check(na > 0.9 and ea < 1e-7*na, "du/da of a Dirichlet value a against central differences: %.3g (max %.3g)", ea, na)
  print(string.format("step:sensitivity: du(t1)/dkappa to %.2g of central differences, every step's tangent along (f, u0) to %.2g, "
                      .. "a Dirichlet value's to %.2g", e/n, worst, ea/na))
end

-- 4c. step sizes that change: adaptive (dt a function: Newton failures retried with a smaller
-- step, the last step clipped to t1), the same sizes given as a list march to the same bits
-- and are differentiable (the running term's trapezoidal rule on the step times); a list
-- of equal sizes gives dt's gradient
do
  local h = lg.parameter("h", 0.1)
  local t = lg.parameter("t", 0)
  local u0 = lg.interpolate(P1, mesh, 5*lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local m = lg.parameter("m", 10)
  local F = lg.integral(mesh:cells(), (u - u0)/h*v + (1 + u^2)*lg.dot(lg.grad(u), lg.grad(v)) - m*(1 + t)*v)
  local bc = lg.essential_bc(mesh:boundary(), v*u)
  local asked = 0
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, t1 = 0.5, time = t, step_size = h,
    nonlinear = true, bc = bc, prefix = "adapt_", monitor = false,
    dt = function(k, tk, last)
      asked = asked + 1
      if not last then return 0.2 end
      if last.failed then return last.dt/2 end
      return last.iterations <= 3 and last.dt*1.5 or last.dt
    end}
  -- MUMPS from the start: a failed Newton solve with PETSc's own LU switches it to MUMPS (the
  -- fallback of nonlinear solves), and the replay below, a new problem, would start without
  lg.options("-adapt_snes_max_it 4 -adapt_pc_factor_mat_solver_type mumps")
  local uA, info = step:solve()
  local times = step:times()
  T.check(info.retries >= 3 and info.steps == #times - 1 and asked == info.steps + info.retries,
          "adaptive march: %d steps, %d retries, %d calls of dt", info.steps, info.retries, asked)
  T.check(math.abs(times[#times] - 0.5) < 1e-15 and times[2] < 0.2/4, "adaptive times: first %.4g, last %.17g", times[2], times[#times])
  local sizes = step:sizes()
  T.check(#sizes == info.steps and math.abs(times[3] - times[2] - sizes[2]) < 1e-15, "step:sizes()")
  local fixed = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = sizes, time = t, step_size = h,
                                nonlinear = true, bc = bc, prefix = "adapt_", monitor = false}
  local uF = fixed:solve()
  local a, b = uA:values(), uF:values()
  for i = 1, #a do T.check(a[i] == b[i], "the list of the adaptive march's sizes marches to other values at dof %d", i) end
  T.fails(function() lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u^2)},
                                           control = m} end, "lg.reduced_functional", "adaptive")
  T.fails(function() step:sensitivity(m) end, "step:sensitivity", "adaptive")
  T.fails(function() lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, t1 = 0.5, nonlinear = true,
                                     dt = function() return 0.1 end} end, "lg.time_problem", "step_size")
  T.fails(function() lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, t1 = 0.6, step_size = h,
                                     nonlinear = true, dt = {0.1, 0.2, 0.2}} end, "lg.time_problem", "end at 0.5")
  local bad = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, t1 = 0.5, step_size = h, nonlinear = true,
                              bc = bc, monitor = false, dt = function() return -1 end}
  T.fails(function() bad:times() end, "step:times", "after step:solve")
  T.fails(function() bad:solve() end, "step:solve", "must return a positive number")
  T.check(#bad:times() == 1, "a march that failed at its first step: %d step times", #bad:times())
  -- differentiable: the list's Taylor test, a running term on uneven steps
  local J = lg.functional{final = lg.integral(mesh:cells(), u^2), running = lg.integral(mesh:cells(), u*x)}
  local rf = lg.reduced_functional{problem = fixed, functional = J, control = {m, u0}, checkpoints = 3}
  local tt = lg.taylor_test(rf, {10, 5*lg.sin(pi*x)*lg.sin(pi*y)}, {1, x*y*(1 - x)}, {h = 0.05, steps = 4})
  local r = rate_ok(tt, "steps of the adaptive march's sizes")
  -- equal sizes as a list: dt's value and gradient
  local lin = lg.integral(mesh:cells(), (u - u0)/h*v + lg.dot(lg.grad(u), lg.grad(v)) - m*(1 + t)*v)
  local function rfof(dt)
    local st = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = lin, dt = dt, t1 = 0.5, time = t,
                               step_size = h, bc = bc, monitor = false}
    return lg.reduced_functional{problem = st, functional = lg.functional{running = lg.integral(mesh:cells(), u*x),
                                 at = {[0.3] = lg.integral(mesh:cells(), u^2)}}, control = m}
  end
  local r1, r2 = rfof(0.1), rfof({0.1, 0.1, 0.1, 0.1, 0.1})
  T.close(r2:value(3), r1:value(3), 1e-13, "a list of equal sizes: the value")
  T.close(r2:gradient(3), r1:gradient(3), 1e-13, "a list of equal sizes: the gradient")
  print(string.format("time_problem: adaptive steps (%d steps, %d retried), replayed from their sizes to the bit, Taylor rate %.3f",
                      info.steps, info.retries, r))
end

-- 4d. option 'scheme': eqn = function(u_t, u, t) returning M(u_t) + A(u, t); backward Euler,
-- Crank-Nicolson (the explicit half at u0 and t - dt) and BDF2 march as the same equations
-- written by hand (to the bit; to rounding where the scheme's own t - dt parameter orders the
-- terms otherwise); theta = 0.7 on two unknowns; a gradient through the
-- Crank-Nicolson form (its hidden t - dt parameter set at every replayed step)
do
  local t, tp = lg.parameter("t", 0), lg.parameter("tp", 0)
  local u0 = lg.interpolate(P1, mesh, lg.sin(pi*x)*lg.sin(pi*y), "u0")
  local u00 = lg.interpolate(P1, mesh, 0.9*lg.sin(pi*x)*lg.sin(pi*y), "u00")
  local dt = 0.05
  local bc = lg.essential_bc(mesh:boundary(), v*u)
  local kappa = lg.parameter("kappa", 1)
  local A = function(w, tt) return kappa*(1 + tt)*(1 + w^2)*lg.dot(lg.grad(w), lg.grad(v)) - x*tt*v end
  local eqn = function(ut, w, tt) return lg.integral(mesh:cells(), ut*v + A(w, tt)) end
  local function mk(o)
    local base = {mesh = mesh, test = v, unknown = u, previous = u0, dt = dt, steps = 6, time = t, bc = bc, nonlinear = true,
                  monitor = false}
    for k, val in pairs(o) do base[k] = val end
    return lg.time_problem(base)
  end
  local function same(what, a, b, tol)
    local va, vb = a:solve():values(), b:solve():values()
    for i = 1, #va do
      T.check(math.abs(va[i] - vb[i]) <= (tol or 0)*math.abs(vb[i]), "%s: scheme and hand-written differ at dof %d: %.17g %.17g",
              what, i, va[i], vb[i])
    end
  end
  same("backward Euler", mk{scheme = "backward_euler", eqn = eqn}, mk{eqn = eqn((u - u0)/dt, u, t)})
  local cn = mk{scheme = "crank_nicolson", eqn = eqn}
  same("Crank-Nicolson", cn, mk{eqn = 0.5*eqn((u - u0)/dt, u, t) + 0.5*eqn((u - u0)/dt, u0, tp),
                                before_step = function(k, tk) tp:set(tk - dt) end}, 1e-14)
  same("BDF2", mk{scheme = "bdf2", eqn = eqn, previous = {u0, u00}}, mk{eqn = eqn((1.5*u - 2*u0 + 0.5*u00)/dt, u, t), previous = {u0, u00}})
  -- two unknowns, theta = 0.7: u_t, u and u0 as tables
  local w, q = lg.unknown(P1, "w"), lg.test(P1, "q")
  local w0 = lg.interpolate(P1, mesh, x*y, "w0")
  local sys = function(ut, uu, tt)
    return lg.integral(mesh:cells(), ut[1]*v + ut[2]*q + lg.dot(lg.grad(uu[1]), lg.grad(v)) + (uu[1] - uu[2])*q
                                     + 0.1*lg.dot(lg.grad(uu[2]), lg.grad(q)) - tt*v)
  end
  local both = {mesh = mesh, test = {v, q}, unknown = {u, w}, previous = {u0, w0}, dt = dt, steps = 6, time = t,
                bc = {bc, lg.essential_bc(mesh:boundary(), q*w)}, monitor = false}
  local o1, o2 = {}, {}
  for k, val in pairs(both) do o1[k], o2[k] = val, val end
  o1.scheme, o1.theta, o1.eqn = "theta", 0.7, sys
  local ut = {(u - u0)/dt, (w - w0)/dt}
  o2.eqn = 0.7*sys(ut, {u, w}, t) + 0.3*sys(ut, {u0, w0}, tp)
  o2.before_step = function(k, tk) tp:set(tk - dt) end
  local a1, b1 = lg.time_problem(o1):solve()
  local a2, b2 = lg.time_problem(o2):solve()
  local va, vb, wa, wb = a1:values(), a2:values(), b1:values(), b2:values()
  for i = 1, #va do
    T.check(math.abs(va[i] - vb[i]) <= 1e-14*math.abs(vb[i]) and math.abs(wa[i] - wb[i]) <= 1e-14*math.abs(wb[i]),
            "theta = 0.7, two unknowns: dof %d differs", i)
  end
  local rf = lg.reduced_functional{problem = cn, functional = lg.functional{final = lg.integral(mesh:cells(), u^2*x)},
                                   control = {kappa, u0}, checkpoints = 3}
  local r = rate_ok(lg.taylor_test(rf, {1, lg.sin(pi*x)*lg.sin(pi*y)}, {0.3, x*y*(1 - x)*(1 - y)}, {h = 0.05, steps = 4}),
                    "Crank-Nicolson by its scheme")
  T.fails(function() mk{scheme = "bdf2", eqn = eqn} end, "lg.time_problem", "bdf2", "2 previous states")
  T.fails(function() mk{scheme = "crank_nicolson", eqn = eqn((u - u0)/dt, u, t)} end, "lg.time_problem", "function(u_t, u, t)")
  T.fails(function() mk{scheme = "leapfrog", eqn = eqn} end, "lg.time_problem", "option 'scheme'")
  T.fails(function() mk{theta = 0.5, eqn = eqn((u - u0)/dt, u, t)} end, "option 'theta' goes with")
  T.fails(function() mk{scheme = "theta", theta = 1.5, eqn = eqn} end, "option 'theta' must be in [0, 1]")
  T.fails(function() mk{scheme = "backward_euler", eqn = function() return 1 end} end, "must return a form")
  print(string.format("time_problem: schemes (backward Euler, Crank-Nicolson, BDF2, theta on two unknowns) equal to the "
                      .. "hand-written steps (1e-14), Taylor rate %.3f through Crank-Nicolson", r))
end

-- 5. refused with a message naming the call
do
  local u0 = lg.interpolate(P1, mesh, x, "u0")
  local F = lg.integral(mesh:cells(), (u - u0)*v + lg.dot(lg.grad(u), lg.grad(v)))
  T.fails(function() lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.3, t1 = 1} end,
          "lg.time_problem", "whole number of steps")
  T.fails(function() lg.time_problem{mesh = mesh, test = v, unknown = u, eqn = F, dt = 0.1, t1 = 1} end, "option 'previous'")
  T.fails(function() lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.1} end, "'t1'", "'steps'")
  T.fails(function() lg.time_problem{mesh = mesh, test = v, unknown = u, previous = {u0, u0}, eqn = F, dt = 0.1, steps = 2} end,
          "the same discrete function")
  local step = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.1, steps = 3, monitor = false}
  local f = lg.control(P1, mesh, "f", 1)
  T.fails(function() lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u0*u)},
                                           control = u0} end, "reads a previous state")
  T.fails(function() lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u)},
                                           control = f} end, "appears in neither")
  T.fails(function() lg.reduced_functional{problem = step, functional = lg.functional{final = lg.integral(mesh:cells(), u)},
                                           control = u0, checkpoints = 0} end, "checkpoints")
  local Ju = lg.functional{final = lg.integral(mesh:cells(), u^2)}
  T.fails(function() lg.reduced_functional{problem = step, functional = Ju, control = u0, checkpoints = {ram = 0, disk = 0}} end,
          "lg.reduced_functional", "at least one")
  T.fails(function() lg.reduced_functional{problem = step, functional = Ju, control = u0, checkpoints = {ram = 1, disc = 2}} end,
          "disc")
  T.fails(function() lg.reduced_functional{problem = step, functional = Ju, control = u0, checkpoints = {ram = 1, disk = 1},
                                           schedule = "revolve"} end, "multistage")
  T.fails(function() lg.reduced_functional{problem = step, functional = Ju, control = u0, checkpoints = 2, schedule = "mixed"} end,
          "schedule \"mixed\" is not provided", "revolve")
  T.fails(function() lg.reduced_functional{problem = step, functional = Ju, control = u0, checkpoints = {ram = 1, disk = 1},
                                           dir = "/proc/no/such"} end, "option 'dir'")
  T.fails(function() lg.reduced_functional{problem = step, functional = Ju, control = u0,
                                           checkpoints = {ram = 1, disk = 1, dir = "/proc/no/such"}} end, "/proc/no/such")
  -- a disk snapshot changed between the value's march and the gradient is refused, not read
  local long = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.1, steps = 8, monitor = false}
  local rfk = lg.reduced_functional{problem = long, functional = Ju, control = u0, checkpoints = {ram = 1, disk = 2}}
  rfk:value(x)
  local dir = rfk:stats().dir
  for _, name in ipairs(files(dir)) do
    local fh = io.open(dir .. "/" .. name, "r+b")
    fh:seek("set", 16)
    fh:write("\1\2\3\4")
    fh:close()
  end
  T.fails(function() rfk:gradient() end, "rf:gradient", "checkpoint file", "is not the state of step")
  T.check(#files(dir) == 0, "checkpoint files left after an error: %d", #files(dir))
  T.fails(function() lg.reduced_functional{problem = step, functional = lg.functional{at = {[0.15] = lg.integral(mesh:cells(), u)}},
                                           control = u0} end, "not at a step's time")
  local a = lg.parameter("a", 0)
  local sd = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.1, steps = 3, monitor = false,
                             bc = lg.essential_bc(mesh:boundary(), v*(u - a))}
  local sq = lg.time_problem{mesh = mesh, test = v, unknown = u, previous = u0, eqn = F, dt = 0.1, steps = 3, monitor = false,
                             bc = lg.essential_bc(mesh:boundary(), v*(u - a^2))}
  local rfd = lg.reduced_functional{problem = sq, functional = lg.functional{final = lg.integral(mesh:cells(), u^2)}, control = a}
  T.fails(function() rfd:hessian(1) end, "rf:hessian", "essential condition nonlinearly")
  print("time_problem: bad input refused with messages")
end

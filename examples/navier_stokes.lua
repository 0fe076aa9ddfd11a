-- navier_stokes.lua — the steady lid-driven cavity at Re = 100: incompressible
-- Navier-Stokes with Taylor-Hood elements, the convection term written as it reads,
-- (grad u) u, Newton's method with the engine's Jacobian, started from the Stokes flow and
-- continued in the Reynolds number (10, 100). The pressure's constant is the null space.
-- Checks the primary vortex: the minimum of u_x on the vertical centreline against Ghia,
-- Ghia & Shin (1982), -0.21090 at y = 0.4531 for Re = 100. The lid at speed 1 makes the
-- corners singular and the convergence slow: -0.20205 at 32x32 (4.2% off), -0.20798 at
-- 64x64 (1.4%).
-- Run: lugal examples/navier_stokes.lua [n]
local lg = require "lugal"
local n = tonumber(arg and arg[1]) or 32
local mesh = lg.mesh.rectangle{nx = n, diagonal = "crossed"}
local V, Q = lg.vector(lg.lagrange(2)), lg.lagrange(1)
local u, p = lg.unknown(V, "u"), lg.unknown(Q, "p")
local v, q = lg.test(V, "v"), lg.test(Q, "q")
local Re = lg.parameter("Re", 1)
local F = lg.integral(mesh:cells(), 1/Re*lg.inner(lg.grad(u), lg.grad(v)) + lg.dot(lg.dot(lg.grad(u), u), v)
                                     - p*lg.div(v) - q*lg.div(u))
local bc = {lg.essential_bc(mesh:boundary("left", "right", "bottom"), lg.dot(v, u)),
            lg.essential_bc(mesh:boundary("top"), lg.dot(v, u - {1, 0}))}
local ns = lg.nonlinear_problem{mesh = mesh, eqn = F, bc = bc, test = {v, q}, unknown = {u, p}, nullspace = p}
local t0 = lg.wtime()
local uh, ph, info
for _, re in ipairs{1, 10, 100} do
  Re:set(re)
  uh, ph, info = ns:solve(uh and {uh, ph})
  print(string.format("navier_stokes: Re = %g, %d Newton iterations, |F| %.1e", re, info.iterations, info.residuals[#info.residuals]))
  assert(info.iterations <= 8, "Newton converges in a few steps from the last solution")
end
-- the pressure's constant (the null space): the solution comes back with its mean at zero
local pmean = lg.integrate(mesh, ph)
assert(math.abs(pmean) < 1e-12, "the pressure has mean zero, as nullspace = p promises: " .. pmean)
-- the centreline x = 1/2: the minimum of u_x
local umin, ymin = math.huge, 0
for i = 0, 400 do
  local yy = i/400
  local ux = uh(0.5, yy)
  if ux < umin then umin, ymin = ux, yy end
end
mesh:write("navier_stokes.vtu", {velocity = uh, pressure = ph})
print(string.format("navier_stokes: %dx%d crossed, %d dofs, %.2f s: min u_x on x = 1/2 is %.5f at y = %.4f (Ghia et al.: -0.21090 at 0.4531)",
                    n, n, info.dofs, lg.wtime() - t0, umin, ymin))
assert(math.abs(umin + 0.21090) < (n >= 64 and 0.02 or 0.05)*0.21090, "the centreline minimum near Ghia et al.'s")
assert(math.abs(ymin - 0.4531) < 0.03, "at the right height")

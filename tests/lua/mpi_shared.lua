-- mpi_shared.lua — cases that tests/lua/mpi_cases.lua (meshes whole on every rank) and
-- mpi_dist.lua (distributed meshes, -lugal_distribute) both compare with the serial run:
-- Bratu by Newton, a heat loop on quadrilaterals, vector P2 elasticity with CG + GAMG and
-- the rigid body modes, SIPG with interior facets. require("mpi_shared")(lg, out), out(name, class, value) printing a line.
return function(lg, out)
local x, y, pi = lg.x, lg.y, math.pi

-- Bratu, Newton to a tight tolerance
do
  local mesh = lg.mesh.rectangle{nx = 16}
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "ub"), lg.test(P1, "vb")
  local prob = lg.nonlinear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - 3*lg.exp(u)*v),
                                    bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u, prefix = "bratu_"}
  lg.options("-bratu_snes_rtol 1e-14 -bratu_snes_atol 1e-13")
  local uh, info = prob:solve()
  out("bratu_norm", "iter", math.sqrt(lg.integrate(mesh, uh*uh)))
  out("bratu_newton", "count", info.iterations)
end

-- heat: a backward Euler loop, the previous step a discrete function (interpolated, then
-- assigned from each solution), on quadrilaterals
do
  local mesh = lg.mesh.rectangle{nx = 16, cell = "quadrilateral"}
  local Q = lg.lagrange(1)
  local u, v = lg.unknown(Q, "uh_"), lg.test(Q, "vh_")
  local uold = lg.interpolate(Q, mesh, lg.sin(pi*x)*lg.sin(pi*y), "uold")
  local dt = 0.01
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), (u - uold)*v + dt*lg.dot(lg.grad(u), lg.grad(v))),
                                 bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  for _ = 1, 5 do local s = prob:solve(); uold:assign(s) end
  out("heat_norm", "direct", math.sqrt(lg.integrate(mesh, uold*uold)))
end

-- vector P2 elasticity on tetrahedra with CG + GAMG (the rigid body modes), a tight tolerance
do
  local mesh = lg.mesh.box{nx = 4, ny = 2, nz = 2, x1 = 2}
  local V = lg.vector(lg.lagrange(2), 3)
  local u, v = lg.unknown(V, "ue"), lg.test(V, "ve")
  local function eps(w) return lg.sym(lg.grad(w)) end
  local a = lg.integral(mesh:cells(), 2*lg.inner(eps(u), eps(v)) + lg.div(u)*lg.div(v) - lg.dot({0, 0, -0.01}, v))
  local prob = lg.linear_problem{mesh = mesh, eqn = a, bc = lg.essential_bc(mesh:boundary("left"), lg.dot(v, u)),
                                 test = v, unknown = u, prefix = "el_", symmetric = true}
  lg.options("-el_ksp_type cg -el_pc_type gamg -el_ksp_rtol 1e-11")
  local uh = prob:solve()
  out("elasticity_norm", "iter", math.sqrt(lg.integrate(mesh, lg.dot(uh, uh))))
  out("elasticity_ndof", "count", uh:ndof())
end

-- discontinuous Galerkin (SIPG) with interior facets (on a distributed mesh a discontinuous
-- field's rows are its owned cells', whose facets have both sides on the rank)
do
  local mesh = lg.mesh.rectangle{nx = 8}
  local D = lg.discontinuous(1)
  local u, v = lg.unknown(D, "ud"), lg.test(D, "vd")
  local n, h, s = lg.normal(), 1/8, 10
  local ue = lg.sin(pi*x)*lg.sin(pi*y)
  local F, B = mesh:interior_facets(), mesh:boundary()
  local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - 2*pi^2*ue*v)
    + lg.integral(F, -lg.dot(lg.avg(lg.grad(u)), lg.jump(v, n)) - lg.dot(lg.avg(lg.grad(v)), lg.jump(u, n)) + s/h*lg.dot(lg.jump(u, n), lg.jump(v, n)))
    + lg.integral(B, -lg.dot(lg.grad(u), n)*v - lg.dot(lg.grad(v), n)*u + s/h*u*v)
  local uh = lg.linear_problem{mesh = mesh, eqn = eqn, test = v, unknown = u}:solve()
  out("dg_L2", "direct", math.sqrt(lg.integrate(mesh, (uh - ue)^2)))
  out("dg_jumps", "direct", lg.integrate(F, lg.dot(lg.jump(uh, n), lg.jump(uh, n))))
  out("dg_ndof", "count", uh:ndof())
end
end

-- Newton's default linear solver (src/assemble/problem/problem_solve.c, newton_matrix): each
-- Jacobian of a large nonlinear problem (here the size lowered by -lugal_iterative_min) gets
-- CG with GAMG where it is symmetric with a positive diagonal (the second derivative of an
-- energy), GMRES with GAMG where it is unsymmetric, GMRES from then on after CG met an
-- indefinite Jacobian, and the direct solver with -lugal_iterative 0. For CG the essential
-- columns are eliminated; the adjoint corrects for them (column_correction), so the
-- gradients of a Dirichlet control and a source parameter are the direct solver's.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z, pi = lg.x, lg.y, lg.z, math.pi
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local c, s = lg.parameter("c", 0.3), lg.parameter("s", 1.0)
local mesh = lg.mesh.box{nx = 14}

-- ∇u·∇v + 10 u³ v − f v (+ conv u ∂u/∂x v), u = c (1 + x) on the boundary; J = ∫ (u − 1/2)²
local function solve(conv, prefix)
  local f = s*3*pi^2*lg.sin(pi*x)*lg.sin(pi*y)*lg.sin(pi*z)
  local prob = lg.nonlinear_problem{mesh = mesh, test = v, unknown = u, prefix = prefix,
    eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) + 10*u^3*v - f*v + conv*u*lg.grad(u)[1]*v),
    bc = lg.essential_bc(mesh:boundary(), v*(u - c*(1 + x)))}
  local uh, info = prob:solve()
  local rf = lg.reduced_functional{problem = prob, functional = lg.functional(lg.integral(mesh:cells(), (u - 0.5)^2)),
                                   control = {c, s}}
  local gc, gs = rf:gradient()
  -- the tangent solve: du/dc, and dJ/dc from it
  local duc = prob:sensitivity(c)
  return uh, info, rf:value(), gc, gs, lg.integrate(mesh, 2*(uh - 0.5)*duc)
end

lg.options("-lugal_iterative_min 2000")
local a, ia, Ja, gca, gsa, dca = solve(0)
local b, ib, Jb, gcb, gsb = solve(3)
lg.options("-lugal_iterative 0")
local a0, ia0, Ja0, gca0, gsa0 = solve(0)
local b0, ib0, Jb0, gcb0, gsb0 = solve(3)
-- the user's CG (not lugal's default): the essential columns are eliminated for it too; before,
-- CG ran on the unsymmetric matrix of replaced rows and Newton's fourth step failed
lg.options("-lugal_iterative 1 -cg_ksp_type cg -cg_pc_type gamg -cg_ksp_rtol 1e-12 -gm_ksp_type gmres -gm_pc_type ilu -gm_ksp_rtol 1e-12")
local au, iau, Jau, gcau, gsau = solve(0, "cg_")
local bu, ibu, Jbu, gcbu = solve(3, "gm_")
T.check(ia.solver == "cg/gamg", "a symmetric Jacobian (an energy's) gets CG with GAMG, got %s", ia.solver)
T.check(ib.solver == "gmres/gamg", "an unsymmetric one (u ∂u/∂x) gets GMRES with GAMG, got %s", ib.solver)
T.check(not ia0.solver:find("gamg") and not ib0.solver:find("gamg"), "-lugal_iterative 0: direct, got %s, %s", ia0.solver, ib0.solver)
T.check(ia.iterations == ia0.iterations and ib.iterations == ib0.iterations,
        "the same Newton iterations as the direct solver (%d %d against %d %d)", ia.iterations, ib.iterations, ia0.iterations, ib0.iterations)
T.check(ia.linear_iterations < 30 * ia.iterations, "GAMG's CG: %d iterations in %d Newton steps", ia.linear_iterations, ia.iterations)
local da = math.sqrt(lg.integrate(mesh, (a - a0)^2) / lg.integrate(mesh, a0^2))
local db = math.sqrt(lg.integrate(mesh, (b - b0)^2) / lg.integrate(mesh, b0^2))
T.check(da < 1e-9 and db < 1e-9, "the solutions are the direct solver's (relative L2 %.2e, %.2e)", da, db)
local function close(p, q, tol) return math.abs(p - q) <= tol * math.abs(q) end
T.check(close(Ja, Ja0, 1e-10) and close(Jb, Jb0, 1e-10), "J %.12e %.12e against %.12e %.12e", Ja, Jb, Ja0, Jb0)
T.check(close(gca, gca0, 1e-8) and close(gsa, gsa0, 1e-8),
        "CG's gradient (columns eliminated, corrected): dJ/dc %.12e dJ/ds %.12e against %.12e %.12e", gca, gsa, gca0, gsa0)
T.check(close(gcb, gcb0, 1e-8) and close(gsb, gsb0, 1e-8),
        "GMRES's gradient: dJ/dc %.12e dJ/ds %.12e against %.12e %.12e", gcb, gsb, gcb0, gsb0)
T.check(close(dca, gca0, 1e-8), "the tangent solve's dJ/dc %.12e against the adjoint's %.12e", dca, gca0)
T.check(iau.solver == "cg/gamg" and close(gcau, gca0, 1e-8) and close(gsau, gsa0, 1e-8),
        "the user's CG (%s): dJ/dc %.12e dJ/ds %.12e against %.12e %.12e", iau.solver, gcau, gsau, gca0, gsa0)
T.check(ibu.solver == "gmres/ilu" and close(gcbu, gcb0, 1e-8), "the user's GMRES (%s): dJ/dc %.12e against %.12e", ibu.solver, gcbu, gcb0)

-- a Neo-Hookean beam, a vector field: CG with GAMG and the rigid body modes as its near null
-- space (without them GAMG's CG takes 100 and more iterations per step); pulled at its end,
-- the first iterate's Jacobian is indefinite: GMRES takes over, and the gradient of the
-- pull (a Dirichlet value) is the direct solver's
local beam = lg.mesh.box{nx = 30, ny = 6, nz = 6, x1 = 1, y1 = 0.2, z1 = 0.2}
local V = lg.vector(P1)
local w, q = lg.unknown(V, "w"), lg.test(V, "q")
local pull = lg.parameter("pull", 0)
local E, nu = 1e3, 0.3
local mu, lambda = E/(2*(1 + nu)), E*nu/((1 + nu)*(1 - 2*nu))
local F = lg.identity(3) + lg.grad(w)
local Jd = lg.det(F)
local psi = mu/2*(lg.tr(lg.dot(lg.transpose(F), F)) - 3) - mu*lg.log(Jd) + lambda/2*lg.log(Jd)^2
local function beam_solve()
  local prob = lg.nonlinear_problem{mesh = beam, test = q, unknown = w,
    eqn = lg.derivative(lg.integral(beam:cells(), psi - lg.dot({0, 0, -0.5}, w)), w, q),
    bc = {lg.essential_bc(beam:boundary("left"), lg.dot(q, w)), lg.essential_bc(beam:boundary("right"), q[1]*(w[1] - pull))}}
  local wh, info = prob:solve()
  local rf = lg.reduced_functional{problem = prob, functional = lg.functional(lg.integral(beam:cells(), w[3]^2)), control = pull}
  return wh, info, rf:value(), rf:gradient()
end
lg.options("-lugal_iterative_min 2000")
local w1, i1 = beam_solve()
T.check(i1.solver == "cg/gamg" and i1.linear_iterations < 40 * i1.iterations,
        "the beam: CG with GAMG and the rigid body modes, %d iterations in %d Newton steps (%s)", i1.linear_iterations, i1.iterations, i1.solver)
pull:set(0.02)
local w2, i2, J2, g2 = beam_solve()
lg.options("-lugal_iterative 0")
local w3, i3, J3, g3 = beam_solve()
lg.options("-lugal_iterative 1 -lugal_iterative_min 20000")
T.check(i2.solver == "gmres/gamg", "pulled: CG meets an indefinite Jacobian, GMRES takes over, got %s", i2.solver)
local dw = math.sqrt(lg.integrate(beam, lg.dot(w2 - w3, w2 - w3)) / lg.integrate(beam, lg.dot(w3, w3)))
T.check(dw < 1e-9 and close(J2, J3, 1e-9) and close(g2, g3, 1e-7),
        "pulled: the direct solver's solution (relative L2 %.2e), J %.12e (%.12e) and dJ/dpull %.12e (%.12e)", dw, J2, J3, g2, g3)
-- Navier–Stokes (3D Taylor–Hood channel, Re = 20): GMRES with the Schur complement fieldsplit
-- for Newton's steps, and for the adjoint (unsymmetric: the same fieldsplit on the explicit
-- transpose, saddle_transpose_solve) without falling back to the direct solver
local chan = lg.mesh.box{nx = 4}
local V2, Q1 = lg.vector(lg.lagrange(2)), P1
local nu_, np_ = lg.unknown(V2, "nu_"), lg.unknown(Q1, "np_")
local nv_, nq_ = lg.test(V2, "nv_"), lg.test(Q1, "nq_")
local amp, Re = lg.parameter("amp", 1), lg.parameter("Re", 20)
local function ns_solve()
  local prob = lg.nonlinear_problem{mesh = chan, test = {nv_, nq_}, unknown = {nu_, np_},
    eqn = lg.integral(chan:cells(), 1/Re*lg.inner(lg.grad(nu_), lg.grad(nv_)) + lg.dot(lg.dot(lg.grad(nu_), nu_), nv_)
                                     - np_*lg.div(nv_) - nq_*lg.div(nu_)),
    bc = {lg.essential_bc(chan:boundary("left"), lg.dot(nv_, nu_ - {amp*16*y*(1 - y)*z*(1 - z), 0, 0})),
          lg.essential_bc(chan:boundary("front", "back", "bottom", "top"), lg.dot(nv_, nu_))}}
  local uh, ph, info = prob:solve()
  local rf = lg.reduced_functional{problem = prob, control = {amp, Re},
    functional = lg.functional(lg.integral(chan:cells(), lg.inner(lg.grad(nu_), lg.grad(nu_)) + np_^2))}
  local ga, gr = rf:gradient()
  local _, _, after = prob:solve()
  return uh, info, rf:value(), ga, gr, after
end
lg.options("-lugal_iterative_min 1000")
local nsu, nsi, nsJ, nsga, nsgr, nsafter = ns_solve()
lg.options("-lugal_iterative 0")
local nsu0, nsi0, nsJ0, nsga0, nsgr0 = ns_solve()
lg.options("-lugal_iterative 1 -lugal_iterative_min 20000")
T.check(nsi.solver == "gmres/fieldsplit" and nsafter.solver == "gmres/fieldsplit" and nsi.iterations == nsi0.iterations,
        "Navier–Stokes: Newton with the fieldsplit (%s, %d steps against %d), kept after the adjoint (%s)", nsi.solver,
        nsi.iterations, nsi0.iterations, nsafter.solver)
local dns = math.sqrt(lg.integrate(chan, lg.dot(nsu - nsu0, nsu - nsu0)) / lg.integrate(chan, lg.dot(nsu0, nsu0)))
T.check(dns < 1e-9 and close(nsJ, nsJ0, 1e-10) and close(nsga, nsga0, 1e-8) and close(nsgr, nsgr0, 1e-8),
        "Navier–Stokes: the direct solver's velocity (relative L2 %.2e), J %.12e (%.12e), gradient %.12e %.12e (%.12e %.12e)",
        dns, nsJ, nsJ0, nsga, nsgr, nsga0, nsgr0)
print(string.format("newton iterative: CG %d/%d, GMRES %d/%d linear/Newton iterations; dJ/dc %.10e (direct %.10e); beam %s %d/%d, pulled %s, dJ/dpull %.10e (direct %.10e)",
                    ia.linear_iterations, ia.iterations, ib.linear_iterations, ib.iterations, gca, gca0, i1.solver, i1.linear_iterations, i1.iterations, i2.solver, g2, g3))

-- lg.assemble: the raw operators of forms. A functional is a number; a linear form a vector
-- (its entries the integrals against each basis function: they sum to the integral of the
-- coefficient); a bilinear form a matrix (the P1 mass matrix's quadratic form of the
-- interpolant of x is the integral of x^2, the stiffness matrix's row sums vanish), with no
-- boundary conditions applied.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y = lg.x, lg.y
local mesh = lg.mesh.rectangle{nx = 6, ny = 5}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")

T.close(lg.assemble(lg.integral(mesh:cells(), x*y) + lg.integral(mesh:boundary("top"), x)), 0.25 + 0.5, 1e-14,
        "a functional is a number")
local b = lg.assemble(lg.integral(mesh:cells(), (1 + x)*v))
T.check(b:size() == 42 and #b == 42, "one entry per dof (%d)", b:size())
local ones = lg.interpolate(P1, mesh, 1 + 0*x)
T.close(b:dot(ones), 1.5, 1e-14, "the entries of a linear form sum to the integral of its coefficient")
local s = 0
for _, w in ipairs(b:values()) do s = s + w end
T.close(s, 1.5, 1e-14, "values")
T.check(b:norm() > 0 and b:norm() < 1, "norm %.3g", b:norm())
local M = lg.assemble(lg.integral(mesh:cells(), u*v))
local xh = lg.interpolate(P1, mesh, x)
T.close(M:dot(xh, xh), 1/3, 1e-14, "x^T M x = the integral of x^2 (x is in P1)")
T.close(M:dot(ones, ones), 1, 1e-14, "1^T M 1 = the area")
local K = lg.assemble(lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v))))
local r = K:mult(ones)
T.check(r:norm() < 1e-13, "the stiffness matrix annihilates constants (%.2e)", r:norm())
T.close(K:dot(xh, xh), 1, 1e-13, "x^T K x = the integral of |grad x|^2")
T.check(K:nnz() > 0 and K:size() == 42, "nnz %d, size %d", K:nnz(), K:size())
local dense = M:values()
T.close(dense[1][1], M:dot((function() local e = {} for i = 1, 42 do e[i] = i == 1 and 1 or 0 end return e end)(),
                           (function() local e = {} for i = 1, 42 do e[i] = i == 1 and 1 or 0 end return e end)()), 1e-15, "dense entry")
T.check(math.abs(M:norm() - math.sqrt((function() local q = 0 for i = 1, 42 do for j = 1, 42 do q = q + dense[i][j]^2 end end return q end)())) < 1e-14,
        "the Frobenius norm")
-- a vector basis: the load of a vector body force
local V = lg.vector(lg.lagrange(2))
local w = lg.test(V, "w")
local fb = lg.assemble(lg.integral(mesh:cells(), lg.dot({0, -1}, w)))
local ey = lg.interpolate(V, mesh, {0, 1})
T.close(fb:dot(ey), -1, 1e-14, "a vector load against the unit y field is minus the area")
-- bad input
T.fails(function() return lg.assemble(lg.integral(mesh:cells(), u*x)) end, "contains the unknown u but no test function")
T.fails(function() return lg.assemble(lg.integral(mesh:cells(), v*lg.unknown(lg.lagrange(2), "p"))) end, "rectangular")
T.fails(function() return lg.assemble(x) end, "argument 1")
T.fails(function() return M:dot(xh) end, "argument 2")
T.fails(function() return b:dot({1, 2}) end, "the table has 2 entries, 42 expected")
print("lg.assemble: all checks passed")

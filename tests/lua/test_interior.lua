-- Interior facet integrals (mesh:interior_facets()) with jumps and averages: exact values
-- on a four-triangle mesh worked by hand, the normal's orientation (n+ points from the '+'
-- cell to the '-' cell), and zero jumps of discontinuous functions that interpolate a
-- polynomial of their degree (the two sides' quadrature points are the same physical
-- points, for every facet orientation, in 1D, 2D and 3D).
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"
local x, y, z = lg.x, lg.y, lg.z

-- the unit square cut into four triangles at its centre (vertex 5)
local m4 = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {0.5, 0.5}},
                       cells = {{1, 2, 5}, {2, 3, 5}, {3, 4, 5}, {4, 1, 5}}}
local F = m4:interior_facets()
local s2 = math.sqrt(2)
T.close(lg.integrate(F, 1), 2*s2, 1e-14, "the interior facets' length (4 half diagonals)")
-- a piecewise constant w = x + 2y at the centroids: 5/6, 11/6, 13/6, 7/6
local w = lg.interpolate(lg.lagrange(0), m4, x + 2*y, "w")
T.close(lg.integrate(F, lg.jump(w)^2), s2/2*(1 + 1/9 + 1 + 1/9), 1e-14, "∫ jump(w)^2")
T.close(lg.integrate(F, lg.avg(w)), s2/2*6, 1e-14, "∫ avg(w)")
local jn = lg.jump(w, lg.normal())
T.close(lg.integrate(F, lg.dot(jn, jn)), s2/2*(20/9), 1e-14, "∫ |jump(w, n)|^2")
T.close(lg.integrate(F, jn[1]), -2/3, 1e-14, "∫ jump(w, n)_x = sum of (w+ - w-) n+_x |e| (the normal's orientation)")
T.close(lg.integrate(F, jn[2]), -4/3, 1e-14, "∫ jump(w, n)_y")
-- the '+' and '-' values themselves: avg = (plus + minus)/2 and jump = plus - minus
T.close(lg.integrate(F, lg.plus(w) + lg.minus(w)), 2*lg.integrate(F, lg.avg(w)), 1e-14, "plus + minus = 2 avg")
-- a continuous P1 function does not jump; its average is its value
local u = lg.interpolate(lg.lagrange(1), m4, x^2 + y, "u")
T.check(lg.integrate(F, lg.jump(u)^2) < 1e-30, "a continuous function has no jump")
T.close(lg.integrate(F, lg.avg(u)), s2/2*3.5, 1e-14, "∫ avg(u) on the four half diagonals")
-- the gradient of the P1 interpolant of x^2 + y jumps across the half diagonals: by hand
-- (grad u = (1, 1/2), (3/2, 1), (1, 3/2), (1/2, 1) on the four cells) each normal jump
-- (grad u+ - grad u-).n+ times the length is -1/2
local gj = lg.integrate(F, lg.jump(lg.grad(u), lg.normal()))
T.close(gj, -2, 1e-14, "∫ jump(grad u, n)")
T.close(lg.integrate(F, lg.dot(lg.grad(u) - lg.minus(lg.grad(u)), lg.normal())), gj, 1e-14, "jump(grad u, n) = (grad u+ - grad u-).n+")

-- discontinuous functions interpolating polynomials of their degree do not jump, on every
-- interior facet of structured and unstructured (refined) meshes: the '-' side's points are
-- the '+' side's, whatever the facets' vertex order in the two cells
local function nojump(mesh, p, f, what)
  local Fi = mesh:interior_facets()
  local d = lg.interpolate(lg.discontinuous(p), mesh, f, "d")
  local jj = lg.integrate(Fi, lg.jump(d)^2)
  local gg = lg.integrate(Fi, lg.dot(lg.jump(lg.grad(d)), lg.jump(lg.grad(d))))
  local aa = lg.integrate(Fi, lg.avg(d)) - lg.integrate(Fi, d)
  T.check(jj < 1e-24 and gg < 1e-20 and math.abs(aa) < 1e-12,
          "%s: DG%d of a degree-%d polynomial: ∫ jump^2 %.1e, ∫ |jump grad|^2 %.1e, avg - plus %.1e", what, p, p, jj, gg, aa)
end
nojump(lg.mesh.interval{n = 7}, 2, x^2 - x, "interval")
nojump(lg.mesh.rectangle{nx = 4, ny = 3}, 1, 1 + 2*x - 3*y, "rectangle")
nojump(m4:refine():refine(), 2, x^2 - x*y + 3*y^2, "refined four-triangle mesh")
nojump(lg.mesh.box{nx = 2}, 1, 1 + x - 2*y + 3*z, "box")
nojump(lg.mesh.box{nx = 2}:refine(), 2, x*y - z^2 + x, "refined box")
-- a discontinuous function does jump: a DG0 function of x on the unit square's 4x4 mesh
-- jumps by 1/4 across each vertical line, by (x_right - x_left) of the centroids across
-- diagonals (1/12... summed); the total is compared with its count on vertical lines only
local r4 = lg.mesh.rectangle{nx = 4}
local c0 = lg.interpolate(lg.lagrange(0), r4, x, "c0")
T.check(lg.integrate(r4:interior_facets(), lg.jump(c0)^2) > 0.01, "a DG0 function of x jumps")
T.close(lg.integrate(r4:interior_facets(), 1), 3 + 3 + 16*math.sqrt(2)/4, 1e-13, "the 4x4 rectangle's interior facets")

-- errors
T.fails(function() return lg.integrate(m4:cells(), lg.jump(w)) end, "'-' side", "interior_facets")
T.fails(function() return lg.mesh.box{nx = 1, cell = "hexahedron"}:interior_facets() end, "not on hexahedra")
T.fails(function() return lg.jump() end, "lg.jump", "expression")
T.fails(function() return lg.jump(w, 1) end, "lg.jump", "normal")
print("interior facets: all checks passed")

-- problems with interior facet terms: SIPG is consistent, so it reproduces a linear
-- solution exactly with DG1 (two-cell element matrices in the pattern and the scatter,
-- every facet orientation of a refined tetrahedral mesh), scalar and vector (block layout),
-- linear and nonlinear
local function sipg(mesh, V, ue, nonlinear, vec)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local n, sigma = lg.normal(), 20
  local h = 1/4
  local function g(w) return lg.grad(w) end
  local function ip(a, b) return vec and lg.inner(a, b) or lg.dot(a, b) end
  local jumpn = function(w) return vec and lg.outer(lg.jump(w), n) or lg.jump(w, n) end
  local eqn = lg.integral(mesh:cells(), ip(g(u), g(v)))
    + lg.integral(mesh:interior_facets(), -ip(lg.avg(g(u)), jumpn(v)) - ip(lg.avg(g(v)), jumpn(u)) + sigma/h*ip(jumpn(u), jumpn(v)))
    + lg.integral(mesh:boundary(), -lg.dot(lg.dot(g(u), n), v) - lg.dot(lg.dot(g(v), n), u - ue) + sigma/h*lg.dot(u - ue, v))
  local mk = nonlinear and lg.nonlinear_problem or lg.linear_problem
  local uh = mk{mesh = mesh, eqn = eqn, test = v, unknown = u}:solve()
  return math.sqrt(lg.integrate(mesh, lg.dot(uh - ue, uh - ue)))
end
T.check(sipg(lg.mesh.rectangle{nx = 4}, lg.discontinuous(1), 1 + 2*x - y) < 1e-11, "SIPG DG1 on triangles: a linear solution exactly")
T.check(sipg(lg.mesh.rectangle{nx = 4}, lg.discontinuous(2), x*x - y*y + x*y) < 1e-10, "SIPG DG2: a harmonic quadratic exactly")
T.check(sipg(lg.mesh.box{nx = 2}:refine(), lg.discontinuous(1), 1 + x - 2*y + 3*z) < 1e-11, "SIPG DG1 on tetrahedra: exact")
T.check(sipg(lg.mesh.rectangle{nx = 4}, lg.discontinuous(1), 1 + 2*x - y, true) < 1e-11, "SIPG through Newton: exact")
local vx = lg.vector(lg.discontinuous(1))
T.check(sipg(lg.mesh.rectangle{nx = 4}, vx, lg.list{1 + x, 2*y - x}, false, true) < 1e-11, "vector SIPG (B x B blocks): exact")

-- SIPG rates against a smooth solution: L2 p + 1 and broken H1 p (cellwise gradients)
do
  local ue = lg.sin(math.pi*x)*lg.sin(math.pi*y) + x
  local fsrc = 2*math.pi^2*lg.sin(math.pi*x)*lg.sin(math.pi*y)
  local function errs(p, N)
    local mesh = lg.mesh.rectangle{nx = N}
    local V = lg.discontinuous(p)
    local u, v = lg.unknown(V, "u"), lg.test(V, "v")
    local n, h, sigma = lg.normal(), 1/N, 10*p*p
    local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - fsrc*v)
      + lg.integral(mesh:interior_facets(), -lg.dot(lg.avg(lg.grad(u)), lg.jump(v, n)) - lg.dot(lg.avg(lg.grad(v)), lg.jump(u, n))
                                              + sigma/h*lg.dot(lg.jump(u, n), lg.jump(v, n)))
      + lg.integral(mesh:boundary(), -lg.dot(lg.grad(u), n)*v - lg.dot(lg.grad(v), n)*(u - ue) + sigma/h*(u - ue)*v)
    local e = lg.linear_problem{mesh = mesh, eqn = eqn, test = v, unknown = u}:solve() - ue
    return math.sqrt(lg.integrate(mesh, e^2)), math.sqrt(lg.integrate(mesh, lg.dot(lg.grad(e), lg.grad(e))))
  end
  for p, Ns in ipairs{{16, 32}, {8, 16}} do
    local a2, a1 = errs(p, Ns[1])
    local b2, b1 = errs(p, Ns[2])
    local r2, r1 = math.log(a2/b2, 2), math.log(a1/b1, 2)
    print(string.format("SIPG DG%d, %d -> %d: L2 rate %.3f, broken H1 rate %.3f", p, Ns[1], Ns[2], r2, r1))
    T.check(math.abs(r2 - (p + 1)) < 0.1, "SIPG DG%d L2 rate %.3f", p, r2)
    T.check(math.abs(r1 - p) < 0.1, "SIPG DG%d broken H1 rate %.3f", p, r1)
  end
end

-- quadrilaterals, straight and distorted (non-affine maps on both sides): DG Q1 and Q2
-- interpolants of functions in their spaces do not jump, and SIPG with DG Q1 reproduces a
-- linear solution (linear in x and y is bilinear in the reference coordinates)
for _, dist in ipairs{false, true} do
  local mesh = lg.mesh.rectangle{nx = 4, ny = 3, cell = "quadrilateral"}
  if dist then
    for k = 1, mesh:nvertices() do
      local a, b = mesh:coordinates(k)
      if a > 0 and a < 1 and b > 0 and b < 1 then mesh:set_coordinates(k, a + 0.06*math.sin(7*k), b + 0.05*math.cos(5*k)) end
    end
  end
  local what = dist and "distorted quadrilaterals" or "quadrilaterals"
  local Fq = mesh:interior_facets()
  if not dist then T.close(lg.integrate(Fq, 1), 5, 1e-14, "the 4x3 quadrilateral grid's interior edges") end
  for p = 1, 2 do
    local g = p == 1 and 1 + 2*x - 3*y + x*y or x*x*y - y*y + x
    local d = lg.interpolate(lg.discontinuous(p), mesh, g, "d")
    local jj = lg.integrate(Fq, lg.jump(d)^2)
    T.check(jj < 1e-28, "%s: DG Q%d interpolant of a Q%d function does not jump (%.1e)", what, p, p, jj)
  end
  local err = sipg(mesh, lg.discontinuous(1), 1 + 2*x - y)
  T.check(err < 1e-12, "%s: SIPG DG Q1 reproduces a linear solution (%.1e)", what, err)
end

-- adjoints through interior facet terms: a DG state whose penalty on the jumps is a field
-- control, a nonlinear one whose jump term is nonlinear in u; the gradient passes the
-- Taylor test (rate 2), with the Hessian rate 3, and the raw gradient's dot with a
-- direction is the directional derivative
do
  local mesh = lg.mesh.rectangle{nx = 4}
  local V = lg.discontinuous(1)
  local u, v = lg.unknown(V, "u"), lg.test(V, "v")
  local fc = lg.control(V, mesh, "fc")
  for _, nonlinear in ipairs{false, true} do
    local jt = nonlinear and (1 + lg.avg(u)^2)*lg.jump(u)*lg.jump(v) or lg.jump(u)*lg.jump(v)
    local eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) + u*v - (1 + x)*v)
      + lg.integral(mesh:interior_facets(), 4*(1 + lg.avg(fc)^2)*jt)
    local mk = nonlinear and lg.nonlinear_problem or lg.linear_problem
    local st = mk{mesh = mesh, test = v, unknown = u, eqn = eqn}
    local rf = lg.reduced_functional{problem = st, control = fc,
      functional = lg.functional(lg.integral(mesh:cells(), u^2) + lg.integral(mesh:interior_facets(), lg.jump(u)^2))}
    local m0, dm = 0.5 + x*y, lg.sin(3*x)*y + 0.2
    local tt = lg.taylor_test(rf, m0, dm, {hessian = true})
    local r1, r2 = tt.rates1[#tt.rates1], tt.rates2[#tt.rates2]
    print(string.format("interior facet adjoint (%s): Taylor rates %.3f, with the Hessian %.3f", nonlinear and "nonlinear" or "linear", r1, r2))
    T.check(math.abs(r1 - 2) < 0.05, "interior facet terms: first-order Taylor rate %.3f", r1)
    T.check(math.abs(r2 - 3) < 0.1, "interior facet terms: second-order Taylor rate %.3f", r2)
    local g = rf:gradient(m0, {riesz = "none"})
    local dmh = lg.interpolate(V, mesh, dm, "dmh")
    local dot = 0
    for i, gi in ipairs(g:values()) do dot = dot + gi*dmh:values()[i] end
    T.close(dot, rf:derivative(dmh, m0), 1e-10, "gradient . dm = the directional derivative")
  end
end
print("interior facet problems: all checks passed")

-- Hard tangles (issue 13): a spiral strip of 1.5 turns whose interior is started from its
-- Tutte embedding (every interior vertex the mean of its grid neighbours, the boundary
-- fixed at the strip's): a third of the cells inverted, knots where every vertex's
-- feasible set is empty. The default untangle must repair it (the global energy stage),
-- with the boundary fixed too, and smoothing by the energy method must reach at least 0.9 of
-- the structured strip's own minimum quality, which the local smoother, never lowering its
-- minimum, cannot. The same in quadrilaterals. Random interior vertices in a star domain. A
-- tetrahedral bar twisted by 360 degrees. Reference shapes on triangles, quadrilaterals and
-- hexahedra.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. arg[0]:match("(.*/)") .. "../../bench/?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local H = require "hard_meshes"

for _, case in ipairs{{30, 10, 0.7}, {40, 16, 0.75}} do
  local mesh, ref = H.spiral(case[1], case[2], case[3])
  local qref = ref:quality("mean_ratio"):min()
  local fixed = mesh:copy()
  local r = mesh:untangle{quiet = true}
  T.check(r.success and r.invalid_before > mesh:ncells()/4, "spiral %dx%d: %d of %d cells inverted, untangled (%d left)",
          case[1], case[2], r.invalid_before, mesh:ncells(), r.invalid_after)
  local rf = fixed:untangle{quiet = true, boundary = "fixed"}
  T.check(rf.success, "spiral %dx%d with the boundary fixed: untangled (%d left)", case[1], case[2], rf.invalid_after)
  local bmax = 0
  for k = 1, fixed:nvertices() do
    local x0, y0 = ref:coordinates(k)
    local x1, y1 = fixed:coordinates(k)
    if k <= case[1] + 1 or k > (case[1] + 1)*case[2] then bmax = math.max(bmax, math.abs(x1 - x0) + math.abs(y1 - y0)) end
  end
  T.check(bmax == 0, "boundary = \"fixed\" kept the strip's long sides (moved by %g)", bmax)
  local loc, auto = mesh:copy(), mesh:copy()
  local sl = loc:smooth{quiet = true, iterations = 50, method = "local"}
  local se = mesh:smooth{quiet = true, method = "energy", iterations = 50}
  -- the default ("auto"): the local method leaves the minimum below 0.3, the energy method
  -- goes on from there (the local method alone was the default and stopped at 0.02-0.11)
  local sa = auto:smooth{quiet = true, iterations = 50}
  print(string.format("spiral %dx%d: after untangle %.4f, local smoothing %.4f, energy smoothing %.4f, default (%s) %.4f, the strip's own %.4f",
                      case[1], case[2], se.min_before, sl.min_after, se.min_after, sa.method, sa.min_after, qref))
  T.check(se.min_after >= 0.9*qref, "energy smoothing reaches 0.9 of the strip's minimum quality (%.4f vs %.4f)", se.min_after, qref)
  T.check(se.min_after > sl.min_after, "energy smoothing beats the local smoother (%.4f vs %.4f)", se.min_after, sl.min_after)
  if sl.min_after < 0.3 then
    T.check(sa.method:find("local, then energy", 1, true) and sa.min_after >= 0.9*se.min_after,
            "the default smoothing (%s) reaches %.4f against the energy method's %.4f", sa.method, sa.min_after, se.min_after)
  end
end
-- the same spirals in quadrilaterals: the global stage sums the energy over each cell's
-- four corners (it only took triangles and tetrahedra, and left 108 and 241 cells
-- inverted); with sliding boundaries a second pass repairs the strip's end, and boundary
-- vertices the stages slid return to their input places where their cells are as valid
-- there, so that energy smoothing (the same corner sums) reaches the strip's own minimum
for _, case in ipairs{{30, 10, 0.7}, {40, 16, 0.75}} do
  local mesh, ref = H.spiral(case[1], case[2], case[3], 1.5, "quadrilateral")
  local qref = ref:quality("corner_condition"):min()
  local fixed = mesh:copy()
  local r = mesh:untangle{quiet = true}
  T.check(r.success and r.invalid_before > mesh:ncells()/4, "quadrilateral spiral %dx%d: %d of %d cells inverted, untangled (%d left, %d passes)",
          case[1], case[2], r.invalid_before, mesh:ncells(), r.invalid_after, r.passes)
  local rf = fixed:untangle{quiet = true, boundary = "fixed"}
  T.check(rf.success, "quadrilateral spiral %dx%d with the boundary fixed: untangled (%d left)", case[1], case[2], rf.invalid_after)
  local loc = mesh:copy()
  local sl = loc:smooth{quiet = true, iterations = 50, method = "local"}
  local se = mesh:smooth{quiet = true, method = "energy", iterations = 50}
  print(string.format("quadrilateral spiral %dx%d: after untangle %.4f, local smoothing %.4f, energy smoothing %.4f, the strip's own %.4f",
                      case[1], case[2], se.min_before, sl.min_after, se.min_after, qref))
  T.check(se.min_after >= 0.9*qref, "quadrilaterals: energy smoothing reaches 0.9 of the strip's minimum corner condition (%.4f vs %.4f)",
          se.min_after, qref)
  T.check(se.min_after > sl.min_after, "quadrilaterals: energy smoothing beats the local smoother (%.4f vs %.4f)", se.min_after, sl.min_after)
  -- the sliding energy smoothing keeps the better of its two passes: here the local slides'
  -- (0.2305 and 0.2069; the optimizer's pass alone 0.2193 and 0.1923). Its fixed round is
  -- one round: on 40x16 a cell the fixed boundary pins near degenerate (2e-6) kept 50
  -- rounds of 100 Newton steps going (5 000 iterations) before the sliding pass
  T.check(se.sliding == "local" and se.min_after > 1.15*qref and se.iterations < 1000,
          "quadrilateral spiral %dx%d, sliding: %s pass kept, min %.4f (the strip's %.4f), %d iterations", case[1], case[2],
          tostring(se.sliding), se.min_after, qref, se.iterations)
end
-- random interior vertices in a star (non-convex) domain: half the cells inverted, some
-- vertices outside the domain; untangled with the boundary fixed and sliding, then smoothed
-- above the polar mesh's own minimum (whose cells near the centre are thin)
for _, case in ipairs{{8, 40, 1}, {12, 60, 7}} do
  local mesh, ref = H.star(case[1], case[2], case[3])
  local slide = mesh:copy()
  local r = mesh:untangle{quiet = true, boundary = "fixed"}
  T.check(r.success and r.invalid_before > mesh:ncells()/3, "star %dx%d: %d of %d cells inverted, untangled (%d left)",
          case[1], case[2], r.invalid_before, mesh:ncells(), r.invalid_after)
  local rs = slide:untangle{quiet = true}
  T.check(rs.success, "star %dx%d with sliding boundaries: untangled (%d left)", case[1], case[2], rs.invalid_after)
  local qref = ref:quality("mean_ratio"):min()
  local se = mesh:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"}
  T.check(se.min_after >= qref, "star %dx%d: smoothed to %.4f, the polar mesh's own minimum %.4f", case[1], case[2], se.min_after, qref)
  local bmax = 0
  for k = ref:nvertices() - case[2] + 1, ref:nvertices() do
    local x0, y0 = ref:coordinates(k)
    local x1, y1 = mesh:coordinates(k)
    bmax = math.max(bmax, math.abs(x1 - x0) + math.abs(y1 - y0))
  end
  T.check(bmax == 0, "star: the boundary stayed (moved by %g)", bmax)
end
-- the smoother's softened first step is kept when the minimum it leaves is at least the
-- start's times the barrier energy's fall: on this 300 x 45 spiral (a thousand Gauss-Seidel
-- sweeps from the straight strip, boundary fixed) it takes the energy to 0.43 of the start's
-- and the minimum to 0.88 of it. Kept, the smoothing takes 10 Newton steps; rejected (the
-- rule before: never below the start's minimum), 16
do
  local m = H.spiral(300, 45, 0.75, nil, nil, 1000)
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local s = m:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"}
  print(string.format("spiral 300x45 (1000 sweeps): smoothed %.4f -> %.4f in %d Newton steps", s.min_before, s.min_after,
                      s.iterations))
  T.check(r.success and s.optimizer == "newton" and s.iterations <= 12 and s.min_after > 0.38,
          "spiral 300x45: smoothed in %d Newton steps (at most 12), minimum %.4f (> 0.38)", s.iterations, s.min_after)
end
-- sliding boundaries in the energy smoother: from one round with the boundary fixed, a pass
-- where the boundary vertices slide along their straight pieces inside Newton and one where
-- they take guarded local steps between rounds; the higher minimum is kept, the higher mean
-- when the minima are within 1e-4. On a perturbed 16² triangle grid both reach the grid's
-- own 0.866 and the optimizer's pass the higher mean, 0.998 (the local slides: 0.980). On
-- the spiral strip 40x8 the optimizer's pass lowers the minimum below the fixed boundary's
-- (its end vertices crowd the fixed corners): the local slides' pass is kept
do
  local m = require "perturbed"("triangle", 16)
  local s = m:smooth{method = "energy", quiet = true}
  T.check(s.sliding == "optimizer" and s.min_after > 0.866 and s.mean_after > 0.995,
          "perturbed 16² triangles, sliding: %s pass kept, min %.4f, mean %.4f", tostring(s.sliding), s.min_after, s.mean_after)
  -- one pass by choice: the optimizer's alone is the fixed round and its own (2 rounds),
  -- the local slides' alone stay at a mean of 0.980
  local so = require "perturbed"("triangle", 16):smooth{method = "energy", quiet = true, sliding = "optimizer"}
  local sl = require "perturbed"("triangle", 16):smooth{method = "energy", quiet = true, sliding = "local"}
  T.check(so.sliding == "optimizer" and so.sweeps == 2 and math.abs(so.mean_after - s.mean_after) < 1e-12,
          "sliding = \"optimizer\": %s, %d rounds, mean %.6f (best %.6f)", tostring(so.sliding), so.sweeps, so.mean_after, s.mean_after)
  T.check(sl.sliding == "local" and sl.min_after > 0.866 and sl.mean_after < 0.99,
          "sliding = \"local\": %s, min %.4f, mean %.4f", tostring(sl.sliding), sl.min_after, sl.mean_after)
  local ok, e = pcall(function() return require "perturbed"("triangle", 4):smooth{sliding = "local"} end)
  T.check(not ok and e:find("option 'sliding' needs method = \"energy\"", 1, true), "sliding without the energy method: %s", tostring(e))
  ok, e = pcall(function() return require "perturbed"("triangle", 4):smooth{method = "energy", sliding = "both"} end)
  T.check(not ok and e:find("must be \"best\", \"optimizer\" or \"local\", got 'both'", 1, true), "a bad sliding: %s", tostring(e))
  local sp = H.spiral(40, 8, 0.75)
  sp:untangle{quiet = true}
  local fx = sp:copy()
  local a = sp:smooth{method = "energy", quiet = true}
  local b = fx:smooth{method = "energy", quiet = true, boundary = "fixed"}
  T.check(a.sliding == "local" and a.min_after > b.min_after + 0.03, "spiral 40x8 sliding: %s pass kept, min %.4f (fixed %.4f)",
          tostring(a.sliding), a.min_after, b.min_after)
end
-- the energy smoother's optimizers: projected Newton (2D's default) converges in a few
-- steps where L-BFGS needs 160 iterations (the random star), to as low an energy; in 3D
-- L-BFGS is the default, and Newton reaches the same mesh on a twisted bar
do
  local function inv(m)
    local q, s = m:quality("mean_ratio"), 0
    for i = 1, #q do s = s + 1 / q[i] end
    return s
  end
  local mesh, ref = H.star(12, 60, 7)
  mesh:untangle{quiet = true, boundary = "fixed"}
  local m2 = mesh:copy()
  local a = mesh:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed"}
  local b = m2:smooth{quiet = true, method = "energy", iterations = 50, boundary = "fixed", optimizer = "lbfgs"}
  print(string.format("star 12x60 smoothed: Newton %d steps, sum 1/q %.4f, min %.4f; L-BFGS %d iterations, sum 1/q %.4f, min %.4f",
                      a.iterations, inv(mesh), a.min_after, b.iterations, inv(m2), b.min_after))
  T.check(a.optimizer == "newton" and b.optimizer == "lbfgs", "2D: Newton by default (%s), L-BFGS on request (%s)", a.optimizer, b.optimizer)
  T.check(a.iterations <= 20 and 4 * a.iterations <= b.iterations,
          "Newton converges in %d steps (at most 20, a quarter of L-BFGS's %d)", a.iterations, b.iterations)
  T.check(inv(mesh) <= inv(m2) * (1 + 1e-6) and a.min_after >= ref:quality("mean_ratio"):min(),
          "Newton's sum of 1/q %.6f at most L-BFGS's %.6f, its minimum %.4f above the polar mesh's", inv(mesh), inv(m2), a.min_after)
  local bar = H.twisted_bar(4, 6, 1)
  bar:untangle{quiet = true, boundary = "fixed"}
  local bar2 = bar:copy()
  local c = bar:smooth{quiet = true, method = "energy", boundary = "fixed"}
  local d = bar2:smooth{quiet = true, method = "energy", boundary = "fixed", optimizer = "newton"}
  T.check(c.optimizer == "lbfgs" and d.optimizer == "newton" and math.abs(c.min_after - d.min_after) < 1e-6 and
          math.abs(c.mean_after - d.mean_after) < 1e-4 and d.mean_after >= d.mean_before,
          "3D: L-BFGS by default; Newton reaches the same minimum (%.6f, %.6f) and mean (%.5f, %.5f)", c.min_after, d.min_after,
          c.mean_after, d.mean_after)
  -- the minimum in a cell that no vertex can move (all three on the fixed boundary): Newton's
  -- result stands at that minimum with a higher mean (its kept iterate compares the minimum
  -- to rounding, measured in other arithmetic than the report's)
  for _, a in ipairs{0.05, 0.13, 0.29} do
    local fan = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {1, 1}, {0, 1}, {0.55, 0.4}, {-a, 0.5}},
                            cells = {{1, 2, 5}, {2, 3, 5}, {3, 4, 5}, {4, 1, 5}, {1, 4, 6}}}
    local r = fan:smooth{method = "energy", quiet = true, boundary = "fixed"}
    T.check(r.optimizer == "newton" and r.min_after == r.min_before and r.mean_after > r.mean_before + 0.01,
            "a fixed minimum %.4f: kept (%.4f), the mean raised %.4f -> %.4f", r.min_before, r.min_after, r.mean_before, r.mean_after)
  end
  T.fails(function() return m2:smooth{method = "energy", optimizer = "bfgs"} end, "mesh:smooth", "optimizer", "newton")
  T.fails(function() return m2:smooth{optimizer = "newton"} end, "mesh:smooth", "optimizer", "needs method")
  T.fails(function() return m2:smooth{method = "energy", measure = "scaled_jacobian", optimizer = "newton"} end, "mesh:smooth",
          "Newton optimizer needs the energy's measure", "mean_ratio")
end
-- a tetrahedral bar (3n x n x n cubes, 4 long) twisted by 360 degrees: boundary vertices at
-- their twisted places, interior vertices left straight; untangled with the boundary fixed,
-- then smoothed to the twisted bar's own minimum quality. Half its interior vertices are
-- around inverted cells: the untangler takes the global energy first, which already gives
-- the bar's own minimum (the pieces' optimization of (3.3) left 0.046)
do
  local mesh, ref = H.twisted_bar(4, 6, 1)
  local qref = ref:quality("mean_ratio"):min()
  local r = mesh:untangle{quiet = true, boundary = "fixed"}
  T.check(r.success and r.invalid_before > 100, "twisted bar: %d inverted tetrahedra untangled (%d left)", r.invalid_before, r.invalid_after)
  -- stage 1's passes only traded violations here: they stop after five without a new best
  -- (100 passes, 32 ms before; stage 2 repairs the rest in 2 ms)
  T.check(r.stages[1].iterations <= 20, "twisted bar: stage 1 gives up when its passes stop gaining (%d passes)", r.stages[1].iterations)
  local qu = mesh:quality("mean_ratio"):min()
  T.check(qu >= 0.9*qref, "twisted bar: untangling alone reaches 0.9 of its minimum quality (%.4f vs %.4f)", qu, qref)
  local se = mesh:smooth{quiet = true, method = "energy", iterations = 30, boundary = "fixed"}
  print(string.format("twisted bar: after untangle %.4f, energy smoothing %.4f, the twisted bar's own %.4f", se.min_before, se.min_after, qref))
  T.check(se.min_after >= 0.9*qref, "twisted bar: energy smoothing reaches 0.9 of its minimum quality (%.4f vs %.4f)", se.min_after, qref)
end
-- a thicker bar: its minimum is a cell with every vertex on the fixed boundary, so the
-- energy smoother keeps its result for the mean (it was thrown away when the minimum did
-- not rise)
do
  local mesh = H.twisted_bar(6, 6, 1)
  mesh:untangle{quiet = true, boundary = "fixed"}
  local se = mesh:smooth{quiet = true, method = "energy", iterations = 30, boundary = "fixed"}
  T.check(se.min_after == se.min_before and se.mean_after > se.mean_before + 1e-3,
          "twisted bar 6: energy smoothing raises the mean quality (%.4f -> %.4f) at the same minimum", se.mean_before, se.mean_after)
end
-- reference shapes: a graded mesh (x -> 3 (x/3)^2, y -> y^2) is the reference; a perturbed
-- copy smoothed by the energy method with {reference = graded} comes back to it (every
-- cell's map from its reference shape a similarity), while smoothing towards regular
-- triangles does not
-- the graded reference mesh of a cell type, and a copy with its interior vertices perturbed
local function graded(cell)
  local ref = lg.mesh.rectangle{nx = 8, ny = 8, x1 = 3, cell = cell}
  for k = 1, ref:nvertices() do local x, y = ref:coordinates(k); ref:set_coordinates(k, 3*(x/3)^2, y^2) end
  return ref
end
-- the largest |dx| + |dy| between two configurations of a 2D mesh
local function distance(a, b)
  local dmax = 0
  for k = 1, a:nvertices() do
    local x0, y0 = b:coordinates(k)
    local x1, y1 = a:coordinates(k)
    dmax = math.max(dmax, math.abs(x1 - x0) + math.abs(y1 - y0))
  end
  return dmax
end
local function perturbed(ref)
  local m = ref:copy()
  math.randomseed(7)
  for k = 1, m:nvertices() do
    local x, y = m:coordinates(k)
    if x > 1e-9 and x < 3 - 1e-9 and y > 1e-9 and y < 1 - 1e-9 then
      m:set_coordinates(k, x + 0.03*x*(math.random() - 0.5), y + 0.03*y*(math.random() - 0.5))
    end
  end
  return m
end
do
  local ref = graded("triangle")
  local a, b = perturbed(ref), perturbed(ref)
  local q0 = a:quality("deformation_quality", {reference = ref}):min()
  local sa = a:smooth{quiet = true, reference = ref}
  local sb = b:smooth{quiet = true, method = "energy", boundary = "fixed"}
  local qa = a:quality("deformation_quality", {reference = ref}):min()
  local qb = b:quality("deformation_quality", {reference = ref}):min()
  local dmax = distance(a, ref)
  print(string.format("reference shapes: relative mean ratio %.4f -> %.8f (report %.8f), %.4f towards regular triangles; distance to the reference %.1e",
                      q0, qa, sa.min_after, qb, dmax))
  T.check(sa.method == "energy" and math.abs(sa.min_after - qa) < 1e-12, "with a reference the report is the relative mean ratio")
  T.check(qa > 0.9999 and q0 < 0.9, "smoothing with reference shapes reaches them (%.6f from %.4f)", qa, q0)
  T.check(dmax < 1e-3, "and puts the vertices back where the reference has them (%.1e)", dmax)
  T.check(qb < 0.5, "smoothing towards regular triangles does not (%.4f)", qb)
  T.fails(function() return a:smooth{quiet = true, reference = ref, method = "local"} end, "mesh:smooth", "reference shapes need method")
  T.fails(function() return a:smooth{quiet = true, reference = lg.mesh.rectangle{nx = 2}} end, "mesh:smooth", "same mesh")
end
-- untangling with reference shapes: the global stage aims at the structured strip's cells
do
  local m1, ref = H.spiral(40, 16, 0.75)
  local m2 = m1:copy()
  local r1 = m1:untangle{quiet = true}
  local r2 = m2:untangle{quiet = true, reference = ref}
  local q1 = m1:quality("deformation_quality", {reference = ref}):mean()
  local q2 = m2:quality("deformation_quality", {reference = ref}):mean()
  print(string.format("untangle with reference shapes: mean relative mean ratio %.4f (without: %.4f)", q2, q1))
  T.check(r1.success and r2.success and q2 > q1, "untangled with and without reference shapes, closer to them with (%.4f > %.4f)", q2, q1)
  T.check(q2 > 0.99, "untangling with reference shapes ends close to them (%.4f)", q2)
  -- in 2D its fully converged rounds take projected Newton steps: 21 in stage 2 where
  -- L-BFGS took 177 iterations
  T.check(r2.stages[2].iterations < 60, "untangling with reference shapes: %d iterations in stage 2 (Newton steps)",
          r2.stages[2].iterations)
  -- quadrilaterals: per corner, each corner aiming at its shape in the strip (the local
  -- stages repair most of this tangle; the vertices they moved then go towards the shapes)
  local m3, qref = H.spiral(40, 16, 0.75, nil, "quadrilateral")
  local m4 = m3:copy()
  local r3, r4 = m3:untangle{quiet = true}, m4:untangle{quiet = true, reference = qref}
  local q3 = m3:quality("deformation_quality", {reference = qref}):mean()
  local q4 = m4:quality("deformation_quality", {reference = qref}):mean()
  print(string.format("untangle quadrilaterals with reference shapes: mean relative mean ratio %.4f (without: %.4f)", q4, q3))
  T.check(r3.success and r4.success and q4 > q3 and q4 > 0.99, "quadrilaterals untangled, closer to the reference shapes with them (%.4f, %.4f)", q4, q3)
  T.fails(function() return m3:untangle{quiet = true, reference = lg.mesh.rectangle{nx = 2}} end, "mesh:untangle", "same mesh")
end
-- smoothing towards reference shapes on quadrilaterals (the graded mesh above) and
-- hexahedra (a sheared box): a perturbed copy comes back to its reference
do
  local ref = graded("quadrilateral")
  local m = perturbed(ref)
  local s = m:smooth{quiet = true, reference = ref}
  local dmax = distance(m, ref)
  T.check(s.method == "energy" and s.min_before < 0.6 and s.min_after > 0.9999 and dmax < 1e-3,
          "quadrilaterals smoothed towards reference shapes: relative mean ratio %.4f -> %.6f, distance %.1e", s.min_before, s.min_after, dmax)
  local b = lg.mesh.box{nx = 4, cell = "hexahedron"}
  local bref, hb = b:copy(), b:copy()
  for k = 1, b:nvertices() do
    local x, y, z = b:coordinates(k)
    bref:set_coordinates(k, 2*x + 0.3*y, y, z + 0.2*x)
    local inside = x > 1e-9 and x < 1 - 1e-9 and y > 1e-9 and y < 1 - 1e-9 and z > 1e-9 and z < 1 - 1e-9
    local dx, dy = inside and 0.04*math.sin(7*k) or 0, inside and 0.04*math.cos(5*k) or 0
    hb:set_coordinates(k, 2*(x + dx) + 0.3*(y + dy), y + dy, z + 0.2*(x + dx))
  end
  local sh = hb:smooth{quiet = true, reference = bref}
  local hmax = 0
  for k = 1, hb:nvertices() do
    local p, q = {bref:coordinates(k)}, {hb:coordinates(k)}
    for j = 1, 3 do hmax = math.max(hmax, math.abs(p[j] - q[j])) end
  end
  print(string.format("reference shapes: quadrilaterals %.4f -> %.6f, hexahedra %.4f -> %.6f (distance %.1e)",
                      s.min_before, s.min_after, sh.min_before, sh.min_after, hmax))
  T.check(sh.min_before < 0.85 and sh.min_after > 0.9999 and hmax < 1e-4,
          "hexahedra smoothed towards reference shapes: %.4f -> %.6f, distance %.1e", sh.min_before, sh.min_after, hmax)
  T.fails(function() return m:smooth{quiet = true, reference = ref, measure = "scaled_jacobian"} end, "mesh:smooth", "corner condition")
end
-- the smallest motion (ALE remap): motion_weight weighs the distance to the input in stage 2
-- and the global stage; global = false keeps to the local stages
do
  local m0, m1 = H.spiral(40, 16, 0.75), H.spiral(40, 16, 0.75)
  local r0, r1 = m0:untangle{quiet = true}, m1:untangle{quiet = true, motion_weight = 1}
  print(string.format("motion weight 1: mean displacement %.3f against %.3f, %d vertices moved against %d",
                      r1.mean_displacement, r0.mean_displacement, r1.moved, r0.moved))
  T.check(r0.success and r1.success and r1.mean_displacement < 0.8*r0.mean_displacement,
          "motion_weight = 1 untangles the spiral with less motion (mean %.3f against %.3f)", r1.mean_displacement, r0.mean_displacement)
  local m2 = H.spiral(40, 16, 0.75)
  local r2 = m2:untangle{quiet = true, global = false}
  T.check(not r2.success and r2.invalid_after < r2.invalid_before, "global = false: the local stages alone leave knots (%d of %d)",
          r2.invalid_after, r2.invalid_before)
  T.fails(function() return m2:untangle{motion_weight = -1} end, "mesh:untangle", "motion_weight", ">= 0")
  T.fails(function() return m2:untangle{global = "no"} end, "mesh:untangle", "global", "boolean")
  T.fails(function() return m2:untangle{global = false, reference = m0} end, "mesh:untangle", "needs the global stage")
end
-- a twisted bar of 144 000 tetrahedra: the tangle's rim holds 49% of the interior vertices
-- in one piece, which the global energy untangles to the rest mesh's minimum (0.3107); the
-- pieces' optimization left 0.0066 and five times the smoothing
do
  local bar = H.twisted_bar(20, 6, 1)
  local r = bar:untangle{quiet = true, boundary = "fixed"}
  local q = bar:quality("mean_ratio")
  print(string.format("bar 20: %d inverted -> %d, minimum mean ratio %.4f", r.invalid_before, r.invalid_after, q:min()))
  T.check(r.success and bar:check() == 0 and q:min() > 0.3, "bar 20 untangled by the global energy: minimum %.4f > 0.3", q:min())
end
-- anisotropic Tutte starts: a spiral of 12 x 30 cells about 40:1 (width 1.0) started from its
-- Tutte embedding. The first pass repairs it: its global energy (regular target shapes) takes
-- projected Newton steps in 2D, where L-BFGS stalled with 142 cells inverted and the run
-- aiming at the Tutte disk's shapes had to follow. Valid, the boundary where it was, and
-- energy smoothing then reaches the strip's own minimum
do
  local m, ref = H.spiral(12, 30, 1.0)
  local m0 = m:copy()
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local s = m:copy():smooth{quiet = true, method = "energy", boundary = "fixed"}
  local qref = ref:quality("mean_ratio"):min()
  local bmax = 0
  for k = 1, m:nvertices() do
    local x0, y0 = m0:coordinates(k)
    local x1, y1 = m:coordinates(k)
    if k <= 13 or k > 13*30 or k % 13 == 1 or k % 13 == 0 then bmax = math.max(bmax, math.abs(x1 - x0) + math.abs(y1 - y0)) end
  end
  print(string.format("anisotropic spiral 12x30: %d inverted -> %d, %d passes, Tutte run tried %s; smoothed %.4f in %d Newton steps (strip's own %.4f)",
                      r.invalid_before, r.invalid_after, r.passes, tostring(r.tutte_tried), s.min_after, s.iterations, qref))
  T.check(r.success and m:check() == 0 and r.passes == 1 and not r.tutte_tried,
          "anisotropic spiral 12x30: %d -> %d invalid, %d passes (1 expected), Tutte run tried: %s (not expected)",
          r.invalid_before, r.invalid_after, r.passes, tostring(r.tutte_tried))
  T.check(bmax == 0, "anisotropic spiral 12x30: the boundary stayed (moved by %g)", bmax)
  T.check(s.min_after >= 0.9*qref, "anisotropic spiral 12x30: energy smoothing reaches 0.9 of the strip's minimum (%.4f vs %.4f)",
          s.min_after, qref)
  -- its full Newton steps gain as much as the linear term predicts (the projected Hessian is
  -- stiffer than the energy along them): doubled steps take 10 Newton steps where steps of
  -- length 1 took 16
  T.check(s.iterations <= 12, "anisotropic spiral 12x30: energy smoothing in %d Newton steps (at most 12 expected)", s.iterations)
  -- a longer strip of 64 x 16 cells (603 of 2048 inverted, more than a quarter): the
  -- harmonic restart of its knot gives a Tutte embedding back, as the input is one, so the
  -- pieces' rings only repeated it while growing to the whole strip; once a knot's restart
  -- gains nothing and over a quarter of the cells are inverted, the global energy comes at
  -- once (stage 2 in 10 Newton steps; the rings and then L-BFGS on the global energy took 94
  -- iterations, and a 320 x 80 strip 3.5 s instead of 0.4)
  local l = H.spiral(64, 16, 0.75)
  local rl = l:untangle{quiet = true, boundary = "fixed"}
  print(string.format("spiral 64x16: %d inverted -> %d, %d passes, stage 2 in %d iterations",
                      rl.invalid_before, rl.invalid_after, rl.passes, rl.stages[2].iterations))
  T.check(rl.success and l:check() == 0 and rl.passes == 1 and rl.stages[2].iterations <= 30,
          "spiral 64x16: %d -> %d invalid, %d passes, stage 2 in %d iterations (1 pass and at most 30 expected)",
          rl.invalid_before, rl.invalid_after, rl.passes, rl.stages[2].iterations)
  -- 8 x 40 cells of the same width (about 60:1): the first pass leaves more than 5% of the
  -- cells inverted. That is a failure of its global energy, which further passes and the other
  -- placement would only restart (they left as many, in 2/3 of the time on 24 such strips):
  -- the run aiming at the cells' shapes in the mesh's Tutte embedding on a circle, which carry
  -- the strip's anisotropy, follows at once and the other placement is not tried. The same in
  -- quadrilaterals (the disk shapes per corner)
  for _, cell in ipairs{"triangle", "quadrilateral"} do
    local a, aref = H.spiral(8, 40, 1.0, 1.5, cell)
    local ra = a:untangle{quiet = true, boundary = "fixed"}
    local sa = a:copy():smooth{quiet = true, method = "energy", boundary = "fixed"}
    local qa = aref:quality(cell == "triangle" and "mean_ratio" or "corner_condition"):min()
    print(string.format("anisotropic %s spiral 8x40: %d inverted -> %d, %d passes, other placement tried %s, Tutte disk shapes kept %s; smoothed %.4f (strip's own %.4f)",
                        cell, ra.invalid_before, ra.invalid_after, ra.passes, tostring(ra.fallback_tried), tostring(ra.tutte_kept), sa.min_after, qa))
    T.check(ra.success and a:check() == 0 and ra.tutte_tried and ra.tutte_kept and not ra.fallback_tried and ra.passes == 2,
            "anisotropic %s spiral 8x40: %d -> %d invalid, %d passes (1 and the Tutte run expected), Tutte shapes kept: %s, other placement tried: %s",
            cell, ra.invalid_before, ra.invalid_after, ra.passes, tostring(ra.tutte_kept), tostring(ra.fallback_tried))
    T.check(sa.min_after >= 0.9*qa, "anisotropic %s spiral 8x40: energy smoothing reaches 0.9 of the strip's minimum (%.4f vs %.4f)",
            cell, sa.min_after, qa)
  end
  -- an annulus (two boundary loops: not a disk) whose inner loop is mirrored, so that no valid
  -- embedding exists: not repaired, never left worse, and no Tutte run (nor an error from one)
  local nA, nrA = 24, 3
  local av, ac, ab = {}, {}, {}
  local function aid(i, j) return j*nA + (i % nA) + 1 end
  for j = 0, nrA do for i = 0, nA - 1 do
    local th, rr = 2*math.pi*i/nA, 1 + j/nrA
    av[#av + 1] = {rr*math.cos(th), (j == 0 and -1 or 1)*rr*math.sin(th)}
  end end
  for j = 0, nrA - 1 do for i = 0, nA - 1 do
    ac[#ac + 1] = {aid(i, j), aid(i + 1, j), aid(i + 1, j + 1)}; ac[#ac + 1] = {aid(i, j), aid(i + 1, j + 1), aid(i, j + 1)}
  end end
  for i = 0, nA - 1 do ab[#ab + 1] = {aid(i, 0), aid(i + 1, 0)}; ab[#ab + 1] = {aid(i, nrA), aid(i + 1, nrA)} end
  local ann = lg.mesh.new{cell = "triangle", vertices = av, cells = ac, boundary = {wall = ab}}
  local ra = ann:untangle{quiet = true, boundary = "fixed"}
  T.check(not ra.success and ra.invalid_after <= ra.invalid_before and not ra.tutte_tried,
          "mirrored annulus: %d -> %d invalid, Tutte run tried: %s (not a disk: never)", ra.invalid_before, ra.invalid_after,
          tostring(ra.tutte_tried))
  -- a run that succeeds by itself never tries the disk shapes
  local ok = H.spiral(30, 10, 0.7):untangle{quiet = true, boundary = "fixed"}
  T.check(ok.success and not ok.tutte_tried, "spiral 30x10: untangled without the Tutte fallback")
end
-- smoothing's softened first Newton steps (untangle_newton.c): the 200 x 25 spiral solved to its
-- Tutte embedding (10 000 triangles, 3% inverted) untangles with a minimum of 0.011, where
-- the barrier's Newton steps raise a corner's quality by a factor of about 1.75 each; with
-- the first two steps on the softened barrier the smoothing takes 9 Newton steps (11 on the
-- barrier alone) to the same minimum, and never below the untangled mesh's minimum
do
  local m = H.spiral_tutte(200, 25, 0.75)
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local q0 = m:quality("mean_ratio"):min()
  local s = m:smooth{quiet = true, method = "energy", boundary = "fixed"}
  local q = m:quality("mean_ratio")
  print(string.format("Tutte-solved spiral 200x25: untangled minimum %.4f, smoothed in %d Newton steps to %.4f (mean %.4f)",
                      q0, s.iterations, q:min(), q:mean()))
  T.check(r.success and q0 < 0.05 and m:check() == 0, "Tutte-solved spiral 200x25: untangled, minimum %.4f below 0.05", q0)
  T.check(s.iterations <= 9 and q:min() > 0.44 and q:mean() > 0.665,
          "Tutte-solved spiral 200x25: smoothing in %d Newton steps (at most 9), minimum %.4f (> 0.44), mean %.4f (> 0.665)",
          s.iterations, q:min(), q:mean())
end
-- on 32 768 free vertices or more (UT_AMG_MIN_ROWS) the softened steps start with the
-- multigrid, and a softened step not kept is solved again to a fifth of the gradient: the
-- 600 x 75 Tutte-solved spiral (45 000 vertices) smooths in 7 Newton steps (its first
-- softened step solved twice), where block Jacobi's first steps at half the gradient took 9
do
  local m = H.spiral_tutte(600, 75, 0.75)
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local s = m:smooth{quiet = true, method = "energy", boundary = "fixed"}
  print(string.format("Tutte-solved spiral 600x75: smoothed in %d Newton steps (%s) to %.4f", s.iterations, s.preconditioner,
                      s.min_after))
  T.check(r.success and s.preconditioner == "multigrid" and s.iterations <= 7 and s.min_after > 0.445,
          "Tutte-solved spiral 600x75: %d Newton steps (at most 7) with the %s, minimum %.4f (> 0.445)", s.iterations,
          s.preconditioner, s.min_after)
end
-- 3D smoothing's handover from L-BFGS to Newton (smooth.c, untangle_lbfgs.c): the untangled
-- twisted bar of 536 238 tetrahedra (over HANDOVER_CELLS) descends steadily through L-BFGS's
-- iterations 10–19, which hand over to Newton: 20 L-BFGS iterations and 7 Newton steps
-- against 160 L-BFGS iterations in two rounds, to the same minimum and a mean as high
do
  local m = H.twisted_bar(31, 6, 1)
  local r = m:untangle{quiet = true, boundary = "fixed"}
  local s = m:smooth{quiet = true, method = "energy", boundary = "fixed"}
  local q = m:quality("mean_ratio")
  print(string.format("twisted bar 31 (%d tetrahedra): smoothed by %s, %d iterations, minimum %.4f, mean %.5f",
                      m:ncells(), s.optimizer, s.iterations, q:min(), q:mean()))
  T.check(r.success and m:check() == 0, "twisted bar 31: untangled")
  T.check(s.optimizer == "newton" and s.iterations <= 40 and q:min() > 0.309 and q:mean() > 0.5573,
          "twisted bar 31: smoothing handed over to Newton (%s), %d iterations (at most 40), minimum %.4f (> 0.309), mean %.5f (> 0.5573)",
          s.optimizer, s.iterations, q:min(), q:mean())
end
print("hard tangles: all checks passed")

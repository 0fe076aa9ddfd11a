-- The quality module from Lua: per-cell arrays (1-based, cell order), statistics,
-- histogram, worst cells, reports, metrics, VTU cell data, and argument errors.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

-- a regular triangle and a right isosceles one
local m = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {0.5, math.sqrt(3)/2}, {0, 1}},
                      cells = {{1, 2, 3}, {1, 2, 4}}}
local q = m:quality("mean_ratio")
T.check(#q == 2, "#q = %d", #q)
T.close(q[1], 1, 1e-14, "mean ratio of the regular triangle")
T.close(q[2], math.sqrt(3)/2, 1e-14, "mean ratio of the right isosceles triangle")
local mn, at = q:min()
T.check(at == 2, "worst cell %d", at)
T.close(q:mean(), (1 + math.sqrt(3)/2)/2, 1e-14, "mean")
local expect = {radius_ratio = 2*(math.sqrt(2) - 1), min_angle = 45, max_angle = 90, min_solid_angle = 0.75,
                sigma_min = math.sin(math.pi/4) / (math.sqrt(3)/2), edge_ratio = math.sqrt(0.5),
                frobenius_condition = math.sqrt(3)/2, signed_measure = 0.5, min_edge = 1, max_edge = math.sqrt(2)}
for name, v in pairs(expect) do T.close(m:quality(name)[2], v, 1e-13, name) end
T.close(m:quality("scaled_jacobian")[1], 1, 1e-14, "scaled Jacobian of the regular triangle")
local tbl = m:quality("min_angle"):totable()
T.close(tbl[1], 60, 1e-12, "totable")
local w = m:quality("mean_ratio"):worst(1)
T.check(w[1].cell == 2, "worst cell")

-- a constant metric that makes the right triangle equilateral: N = [[1, 0], [-1/√3... ]]
-- simpler: M = diag(4, 1) stretches x by 2; the mean ratio follows the mapped cell
local qm = m:quality("mean_ratio", {metric = {{4, 0}, {0, 1}}})
local mapped = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {2, 0}, {1, math.sqrt(3)/2}, {0, 1}},
                           cells = {{1, 2, 3}, {1, 2, 4}}}
local qe = mapped:quality("mean_ratio")
T.close(qm[1], qe[1], 1e-14, "metric mean ratio cell 1")
T.close(qm[2], qe[2], 1e-14, "metric mean ratio cell 2")

-- report and histogram on a generated tetrahedral mesh
local box = lg.mesh.box{nx = 3}
local rep = box:quality_report(true)
T.check(rep.cells == 162 and rep.inverted == 0, "report counts")
T.check(rep.min_dihedral_angle and rep.mean_ratio.min > 0.6 and rep.mean_ratio.max <= 1, "report values")
local h = box:quality("mean_ratio"):histogram(5, 0, 1)
local total = 0
for _, c in ipairs(h.counts) do total = total + c end
T.check(total == 162, "histogram total %d", total)

-- VTU cell data
local path = os.tmpname() .. ".vtu"
box:write(path, {mean_ratio = box:quality("mean_ratio"), scaled_jacobian = box:quality("scaled_jacobian")})
local text = assert(io.open(path)):read("a")
os.remove(path)
T.check(text:find('<CellData>', 1, true) and text:find('Name="mean_ratio"', 1, true), "VTU has the cell data")

-- deformation between two configurations of one mesh
local before = lg.mesh.rectangle{nx = 2, ny = 2}
local after = before:copy()
for i = 1, after:nvertices() do
  local x, y = after:coordinates(i)
  after:set_coordinates(i, 3*x, y)          -- stretch x by 3: singular values 3 and 1
end
T.close(after:quality("deformation_max_sv", {reference = before}):min(), 3, 1e-13, "max singular value")
T.close(after:quality("deformation_quality", {reference = before, p = math.huge}):max(), 1/3, 1e-13, "tau_inf")
T.fails(function() return after:quality("deformation_quality") end, "pass {reference = mesh}")
T.fails(function() return after:quality("deformation_quality", {reference = box}) end, "same mesh")

-- inverted, degenerate and the quadrilateral classes in the report
local qmesh = lg.mesh.rectangle{nx = 3, ny = 3, cell = "quadrilateral"}
local x6, y6 = qmesh:coordinates(6)
qmesh:set_coordinates(6, x6 + 0.45, y6 + 0.4)   -- over its neighbours: some cells invert
local r = qmesh:quality_report(true)
T.check(r.inverted >= 1 and r.degenerate == 0, "inverted %d degenerate %d", r.inverted, r.degenerate)
T.check(r.quadrilaterals.convex + r.quadrilaterals.nonconvex + r.quadrilaterals.crossed + r.quadrilaterals.degenerate == 9,
        "quadrilateral classes add up")
T.check(r.quadrilaterals.nonconvex + r.quadrilaterals.crossed >= 1, "a tangled cell is not convex")
local flat = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {2, 0}, {0, 1}}, cells = {{1, 2, 3}, {1, 2, 4}}}
T.check(flat:quality_report(true).degenerate == 1, "a flat triangle is degenerate")

-- Verdict names: 1/η, 1/κ̃ relations on the two triangles, and an unsigned scaled Jacobian
T.close(m:quality("verdict.aspect_frobenius")[2], 1 / m:quality("mean_ratio")[2], 1e-13, "verdict aspect frobenius")
T.close(m:quality("verdict.shape")[1], 1, 1e-13, "verdict shape of the regular triangle")
local inv = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {0, 1}, {1, 0}}, cells = {{1, 2, 3}}}
T.check(inv:quality("verdict.scaled_jacobian")[1] > 0 and inv:quality("scaled_jacobian")[1] < 0,
        "Verdict's scaled Jacobian is unsigned, lugal's is not")
local vs, eta = box:quality("verdict.shape"), box:quality("mean_ratio")
for i = 1, #vs do T.close(vs[i], eta[i], 1e-12, "Verdict's tetrahedron shape is the mean ratio") end
T.fails(function() return m:quality("verdict.collapse_ratio") end, "does not apply to triangles")

-- errors
T.fails(function() return m:quality("nope") end, "mesh:quality: unknown measure \"nope\"", "mean_ratio", "scaled_jacobian")
T.fails(function() return m:quality("min_dihedral_angle") end, "does not apply to triangles")
T.fails(function() return lg.mesh.rectangle{nx = 2, cell = "quadrilateral"}:quality("mean_ratio") end,
        "does not apply to quadrilaterals")
T.fails(function() return m:quality("mean_ratio", {metric = {{1, 2}, {2, 1}}}) end, "not symmetric positive definite")
T.fails(function() return m:quality("mean_ratio", {metric = {1, 2}}) end, "option 'metric' must be a 2x2 table")
T.fails(function() return m:quality("mean_ratio", {metrc = 1}) end, "unknown option 'metrc'")
T.fails(function() return q[3] end, "quality index 3 out of range 1..2")
print("quality from Lua: ok")

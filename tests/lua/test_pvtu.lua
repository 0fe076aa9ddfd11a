-- Parallel VTK output (.pvtu): a mesh written in pieces (the parts of the mesh's partition:
-- PTScotch's, or where the numbering splits well the cells by their lowest vertex; each
-- piece with the vertices its cells use) reassembles, cell by cell, into the whole mesh's .vtu with the same
-- coordinates, point values (a scalar, a 3D vector, a discontinuous field) and cell values;
-- the collection names every piece and array; a time series writes .pvtu steps; bad
-- options and unwritable pieces are reported.
package.path = arg[0]:match("(.*/)") .. "?.lua;" .. package.path
local T = require "testlib"
local lg = require "lugal"

local dir = os.tmpname()
os.remove(dir)
assert(os.execute("mkdir -p " .. dir))
local x, y, z = lg.x, lg.y, lg.z

local function piece_points(path)
  local pv, n, sizes = T.read_pvtu(path), 0, {}
  for k, p in ipairs(pv.pieces) do n = n + #p.points; sizes[k] = #p.cells end
  return n, sizes, pv
end
if arg[1] == "natural" then -- the child run below, with -lugal_partitioner natural
  T.shuffled_grid(lg, 24, true):write(dir .. "/n.pvtu", {}, {format = "ascii", pieces = 4})
  print("natural points", (piece_points(dir .. "/n.pvtu")))
  os.execute("rm -rf " .. dir)
  os.exit(0)
end

for _, case in ipairs{{mesh = lg.mesh.rectangle{nx = 7, ny = 5}, pieces = 3},
                      {mesh = lg.mesh.box{nx = 3, ny = 4, nz = 2}, pieces = 5},
                      {mesh = lg.mesh.rectangle{nx = 2, ny = 1}, pieces = 7}} do -- 4 cells in 7 pieces: 3 empty
  local m = case.mesh
  local u = lg.interpolate(lg.lagrange(1), m, lg.sin(3*x) + 10*y, "u")
  local w = lg.interpolate(lg.vector(lg.lagrange(1), m:dim()), m, m:dim() == 3 and {x, y*y, z - x} or {x, y*y}, "w")
  local d = lg.interpolate(lg.discontinuous(1), m, x*y + 1, "d")
  local c = lg.interpolate(lg.lagrange(0), m, x - 2*y, "c")
  local id = {}
  for i = 1, m:ncells() do id[i] = i end
  local fields = {u = u, w = w, d = d, c = c, q = m:quality("mean_ratio"), id = id}
  m:write(dir .. "/whole.vtu", fields, {format = "ascii"})
  m:write(dir .. "/split.pvtu", fields, {format = "ascii", pieces = case.pieces})
  local whole, pv = T.read_vtu(dir .. "/whole.vtu"), T.read_pvtu(dir .. "/split.pvtu")
  T.check(#pv.pieces == case.pieces, "%d pieces named in the .pvtu, %d written", #pv.pieces, case.pieces)
  table.sort(pv.names)
  T.check(table.concat(pv.names, ",") == "c,d,id,q,u,w", "the collection declares %s", table.concat(pv.names, ","))
  T.check(T.same_pieces(whole, pv, 0) == m:ncells(), "every cell compared")
  -- a piece holds only the vertices its cells use, fewer than the whole mesh's
  local npts = 0
  for _, p in ipairs(pv.pieces) do npts = npts + #p.points end
  T.check(#pv.pieces[1].points < #whole.points, "piece 1 has %d points of %d", #pv.pieces[1].points, #whole.points)
  T.check(npts > #whole.points, "the pieces share the vertices on their borders (%d points against %d)", npts, #whole.points)
end

-- one piece (a serial run's default) is the whole mesh
local m = lg.mesh.rectangle{nx = 4}
local u = lg.interpolate(lg.lagrange(2), m, x*x - y, "u")
local id = {}
for i = 1, m:ncells() do id[i] = i end
m:write(dir .. "/one.pvtu", {u = u, id = id}, {format = "ascii"})
m:write(dir .. "/one.vtu", {u = u, id = id}, {format = "ascii"})
local one = T.read_pvtu(dir .. "/one.pvtu")
T.check(#one.pieces == 1, "a serial run writes one piece, got %d", #one.pieces)
T.check(T.slurp(dir .. "/one_p0.vtu") == T.slurp(dir .. "/one.vtu"), "a single piece is the whole mesh's file")
-- binary and zlib pieces are as large as their data: 3 pieces of the binary file hold more
-- bytes (the shared points) than the whole file
m:write(dir .. "/bin.pvtu", {u = u}, {pieces = 3})
m:write(dir .. "/zl.pvtu", {u = u}, {format = "zlib", pieces = 3})
for _, s in ipairs{"bin", "zl"} do
  for k = 0, 2 do
    local f = io.open(string.format("%s/%s_p%d.vtu", dir, s, k))
    T.check(f and f:read("a"):find("</VTKFile>", 1, true), "%s piece %d is a complete file", s, k)
  end
end

-- a time series of .pvtu steps
local ser = lg.series(dir .. "/ser.pvd", {pieces = 2, format = "ascii"})
T.check(ser:write(m, {u = u, id = id}, 0.25) == dir .. "/ser_0000.pvtu", "the first step's name")
ser:write(m, {u = u, id = id}, 0.5)
local pvd = T.slurp(dir .. "/ser.pvd")
T.check(pvd:find('timestep="0.5" part="0" file="ser_0001.pvtu"', 1, true), "the .pvd names the .pvtu steps: %s", pvd)
T.check(T.same_pieces(T.read_vtu(dir .. "/one.vtu"), T.read_pvtu(dir .. "/ser_0001.pvtu"), 0) == m:ncells(), "series step")

-- the pieces are the parts of a graph partition, not runs of the cell order: a 24 x 24
-- grid of triangles whose cells and vertices are numbered in a shuffled order, in 4 pieces.
-- The numbering splits poorly, so the pieces are PTScotch's parts: compact (their borders
-- share few vertices) and balanced; pieces in the numbering's order are scattered over the
-- square (almost every vertex in several pieces)
local g = T.shuffled_grid(lg, 24, true)
local gid = {}
for i = 1, g:ncells() do gid[i] = i end
g:write(dir .. "/g.vtu", {id = gid}, {format = "ascii"})
g:write(dir .. "/g.pvtu", {id = gid}, {format = "ascii", pieces = 4})
local npts, sizes, gpv = piece_points(dir .. "/g.pvtu")
T.check(T.same_pieces(T.read_vtu(dir .. "/g.vtu"), gpv, 0) == 1152, "the partitioned pieces reassemble")
for k = 1, 4 do T.check(math.abs(sizes[k] - 288) <= 288 * 0.05, "piece %d holds %d of 1152 cells (balanced: 288)", k, sizes[k]) end
-- 625 vertices; 4 compact quarters share about 2 x 25 border vertices
T.check(npts < 625 * 1.2, "the 4 partitioned pieces hold %d points for 625 vertices", npts)
local r = lg.mesh.rectangle{nx = 24} -- numbered row by row: its order's pieces are strips
r:write(dir .. "/r.pvtu", {}, {format = "ascii", pieces = 4})
T.check(piece_points(dir .. "/r.pvtu") < 625 * 1.2, "strips")
-- the shuffled grid again, in the numbering's order (-lugal_partitioner natural)
local child = T.child("natural -lugal_partitioner natural")
local nn = tonumber(child:match("natural points%s+(%d+)"))
T.check(nn and nn > 625 * 1.5, "a shuffled numbering's order: %s points in 4 pieces (%s)", tostring(nn), child)

-- errors name the function, the option and what was expected
T.fails(function() m:write(dir .. "/x.vtu", {u = u}, {pieces = 2}) end, "mesh:write", "'pieces' is for a .pvtu")
T.fails(function() m:write(dir .. "/x.pvtu", {u = u}, {pieces = 0}) end, "mesh:write", "'pieces' must be a whole number")
T.fails(function() m:write(dir .. "/x.pvtu", {u = u}, {pieces = 1.5}) end, "'pieces' must be a whole number")
T.fails(function() m:write(dir .. "/x.pvtu", {u = u}, {piece = 2}) end, "mesh:write", "piece")
T.fails(function() lg.series(dir .. "/s.pvd", {pieces = "two"}) end, "lg.series", "'pieces'")
T.fails(function() m:write(dir .. "/x.pvt", {u = u}) end, ".vtu or .pvtu")
-- a piece that cannot be written (a folder in its place): the error names it, no collection
assert(os.execute("mkdir -p " .. dir .. "/bad_p1.vtu"))
T.fails(function() m:write(dir .. "/bad.pvtu", {u = u}, {pieces = 2}) end, "mesh:write", "bad_p1.vtu")
T.check(not io.open(dir .. "/bad.pvtu"), "no .pvtu when a piece failed")

os.execute("rm -rf " .. dir)
print("pvtu: pieces reassemble into the whole mesh (2D, 3D, empty pieces), series, errors")

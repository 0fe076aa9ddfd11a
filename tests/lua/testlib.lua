-- testlib.lua — helpers for lugal's Lua tests: checks that raise errors with a message
-- naming what was expected, and rate computations.
local T = {}
T.failed = 0

function T.check(cond, fmt, ...)
  if not cond then error(string.format(fmt or "check failed", ...), 2) end
end

function T.close(a, b, tol, what)
  tol = tol or 1e-12
  if not (math.abs(a - b) <= tol * (1 + math.abs(b))) then
    error(string.format("%s: got %.17g, expected %.17g (tol %g)", what or "value", a, b, tol), 2)
  end
end

-- the call must fail with a message containing each of the given fragments
function T.fails(fn, ...)
  local ok, msg = pcall(fn)
  if ok then error("expected an error, but the call succeeded", 2) end
  msg = tostring(msg)
  for _, frag in ipairs{...} do
    if not msg:find(frag, 1, true) then
      error(string.format("error message %q does not contain %q", msg, frag), 2)
    end
  end
  return msg
end

function T.rate(e1, e2, h1, h2) return math.log(e1 / e2) / math.log(h1 / h2) end

-- the output (stdout and stderr) of this test script run again by the same lugal with the
-- given arguments, before them environment assignments ("OMP_NUM_THREADS=2") if given
function T.child(args, env)
  local h = io.popen(string.format("%s'%s' '%s' %s 2>&1", env and env .. " " or "", arg[-1], arg[0], args or ""))
  local out = h:read("a")
  h:close()
  return out
end

-- a whole file's text
function T.slurp(path)
  local f = assert(io.open(path))
  local s = f:read("a")
  f:close()
  return s
end

-- an ASCII VTU file (as mesh:write(..., {format = "ascii"}) writes it): {points = {{x, y, z},
-- ...}, cells = {{v1, ...}, ...} (1-based), point = {name = {values}}, cell = {name = {values}}}
function T.read_vtu(path)
  local s = T.slurp(path)
  local r = {points = {}, cells = {}, point = {}, cell = {}}
  local function numbers(body)
    local v = {}
    for w in body:gmatch("%S+") do v[#v + 1] = assert(tonumber(w), "a number in " .. path) end
    return v
  end
  for section, body in s:gmatch("<(%a+Data)>(.-)</%1>") do
    for name, arr in body:gmatch('<DataArray[^>]-Name="([^"]*)"[^>]*>(.-)</DataArray>') do
      (section == "PointData" and r.point or r.cell)[name] = numbers(arr)
    end
  end
  local pts = numbers(assert(s:match("<Points>%s*<DataArray[^>]*>(.-)</DataArray>"), "no points in " .. path))
  for i = 1, #pts, 3 do r.points[#r.points + 1] = {pts[i], pts[i + 1], pts[i + 2]} end
  local conn = numbers(s:match('Name="connectivity"[^>]*>(.-)</DataArray>'))
  local off = numbers(s:match('Name="offsets"[^>]*>(.-)</DataArray>'))
  local at = 0
  for _, o in ipairs(off) do
    local c = {}
    for k = at + 1, o do c[#c + 1] = conn[k] + 1 end
    r.cells[#r.cells + 1] = c
    at = o
  end
  local np, nc = s:match('NumberOfPoints="(%d+)" NumberOfCells="(%d+)"')
  T.check(tonumber(np) == #r.points and tonumber(nc) == #r.cells, "%s: %d points and %d cells, the header says %s and %s",
          path, #r.points, #r.cells, np, nc)
  return r
end

-- the pieces of a .pvtu (their files beside it) and the array names it declares
function T.read_pvtu(path)
  local s = T.slurp(path)
  local dir = path:match("^(.*/)") or ""
  local r = {pieces = {}, names = {}}
  for name in s:gmatch('<PDataArray[^>]-Name="([^"]*)"') do r.names[#r.names + 1] = name end
  for src in s:gmatch('<Piece Source="([^"]*)"') do r.pieces[#r.pieces + 1] = T.read_vtu(dir .. src) end
  return r
end

-- the cells of the pieces of a .pvtu are the cells of the whole VTU, each once: the same
-- corners at the same points, the same point values there and cell values, to tol
-- relative. A cell is found by its cell value "id" (its number in the whole mesh) where the
-- files have one, else the pieces' cells taken in order are the whole's. Returns the number
-- of cells compared
function T.same_pieces(whole, pv, tol)
  local n, seen = 0, {}
  local function same(a, b, what)
    T.check(math.abs(a - b) <= tol * math.max(1, math.abs(b)), "%s: %.17g in the pieces, %.17g in the whole", what, a, b)
  end
  for k, p in ipairs(pv.pieces) do
    for i, c in ipairs(p.cells) do
      n = n + 1
      local cell = p.cell.id and math.tointeger(p.cell.id[i]) or n
      T.check(cell and not seen[cell], "piece %d cell %d: cell %s twice", k, i, tostring(cell))
      seen[cell] = true
      local wc = whole.cells[cell]
      T.check(wc and #wc == #c, "piece %d cell %d: no such cell in the whole mesh", k, i)
      for j = 1, #c do
        for d = 1, 3 do same(p.points[c[j]][d], whole.points[wc[j]][d], string.format("cell %d corner %d coordinate %d", cell, j, d)) end
        for name, v in pairs(whole.point) do
          local n = #v // #whole.points
          for q = 1, n do same(p.point[name][n * (c[j] - 1) + q], v[n * (wc[j] - 1) + q], string.format("%s at cell %d corner %d", name, cell, j)) end
        end
      end
      for name, v in pairs(whole.cell) do
        local n = #v // #whole.cells
        for q = 1, n do same(p.cell[name][n * (i - 1) + q], v[n * (cell - 1) + q], string.format("%s on cell %d", name, cell)) end
      end
    end
  end
  T.check(n == #whole.cells, "the pieces hold %d cells, the whole mesh %d", n, #whole.cells)
  return n
end

-- an n x n grid of triangles on the unit square whose cells (and, with vertices = true,
-- vertices) are listed in a shuffled order (a fixed seed): what a mesh generator that
-- numbers without locality gives. Boundary facets are not tagged
function T.shuffled_grid(lg, n, vertices)
  local verts, cells = {}, {}
  for j = 0, n do for i = 0, n do verts[#verts + 1] = {i / n, j / n} end end
  for j = 0, n - 1 do
    for i = 0, n - 1 do
      local a = j * (n + 1) + i + 1
      cells[#cells + 1] = {a, a + 1, a + n + 2}
      cells[#cells + 1] = {a, a + n + 2, a + n + 1}
    end
  end
  local seed = 12345
  local function shuffle(t)
    for i = #t, 2, -1 do
      seed = (seed * 1103515245 + 12345) % 2147483648
      local k = seed % i + 1
      t[i], t[k] = t[k], t[i]
    end
  end
  shuffle(cells)
  if vertices then
    local perm, nv = {}, {}
    for i = 1, #verts do perm[i] = i end
    shuffle(perm)
    for i = 1, #verts do nv[perm[i]] = verts[i] end
    for _, c in ipairs(cells) do for k = 1, 3 do c[k] = perm[c[k]] end end
    verts = nv
  end
  return lg.mesh.new{cell = "triangle", vertices = verts, cells = cells}
end

return T

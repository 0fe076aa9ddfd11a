#!/bin/sh
# test_mpi_dist.sh BUILD — distributed meshes (-lugal_distribute): each rank holds its part
# of the mesh and one layer of ghost cells, never the whole. tests/lua/mpi_dist.lua's
# quantities on 2 and 3 ranks (the generated meshes' numbering split, and PTScotch's
# partition) against the serial run on the whole mesh (direct solves to 1e-10 relative,
# iterative ones to 1e-8, counts within 1); the VTU gathered on rank 0 (the serial file's
# size) and the .pvtu of a piece per rank (reassembling cell by cell into the serial mesh
# and field); each rank holding fewer cells than the mesh; more ranks than cells (empty
# parts); the functions not offered on a distributed mesh yet refusing with a message; an
# inverted cell in one rank's part ending the run with its message; every example,
# distributed on 2 and 3 ranks.
BUILD=$1
. "$(dirname "$0")/mpi_lib.sh"
run() { rn=$1; shift; if [ "$rn" = 1 ]; then "$LUGAL" "$@"; else timeout 300 mpiexec -n "$rn" "$LUGAL" "$@" -lugal_distribute; fi; }

for n in 1 2 3 2p 3p; do
  mkdir -p "$T/$n"
  case $n in *p) opt="-lugal_partitioner ptscotch" ;; *) opt= ;; esac
  run ${n%p} "$ROOT/tests/lua/mpi_dist.lua" "$T/$n" "$ROOT" $opt -lugal_verbose > "$T/out$n" 2> "$T/err$n" ||
    { tail -n 20 "$T/err$n"; fail "mpi_dist on $n ranks"; }
done
for n in 2 3 2p 3p; do
  [ "$(wc -l < "$T/out1")" = "$(wc -l < "$T/out$n")" ] || fail "$n ranks printed $(wc -l < "$T/out$n") lines, 1 rank $(wc -l < "$T/out1")"
  paste "$T/out1" "$T/out$n" | awk -v what="$n distributed ranks" -f "$ROOT/tests/sh/compare_ranks.awk" || exit 1
  # each rank held its part and a ghost layer of the first mesh (24 x 24, 1152 cells), not
  # the whole: "[lugal] distribute: rank R holds C cells (O owned, G ghosts) ..."
  grep "distribute: rank [0-9]* holds" "$T/err$n" | head -n ${n%p} | tr -d '(' | awk -v n=${n%p} '
    { k++; own += $8; if ($6 + 0 >= 1152) whole = 1 }
    END { if (k != n || own != 1152 || whole) { print "FAIL: the parts of " n " ranks: " k " reports, " own " owned cells, whole " whole; exit 1 } }' || exit 1
  # the generated mesh made rank by rank (its window of rows), not cut from a whole mesh on
  # rank 0, where the numbering's runs are the partition; with PTScotch's on 2 and 3 ranks,
  # rank 0 cuts it (from 4 ranks on the ranks partition it: test_mpi_read.sh)
  made=$(grep "distribute: rank [0-9]* holds" "$T/err$n" | head -n ${n%p} | grep -c "generated here")
  case $n in
    *p) [ "$made" = 0 ] || fail "$n ranks: PTScotch's partition, yet $made ranks generated their own parts" ;;
    *) [ "$made" = "$n" ] || fail "$n ranks: $made ranks generated their own part of the 24 x 24 mesh, expected $n" ;;
  esac
  [ -s "$T/$n/poisson.vtu" ] || fail "no VTU gathered on $n ranks"
  [ "$(wc -c < "$T/1/poisson.vtu")" = "$(wc -c < "$T/$n/poisson.vtu")" ] || fail "the gathered VTU of $n ranks differs in size from the serial one"
done
grep -q "distribute: rank 1 holds" "$T/err2" || fail "no distribution report on 2 ranks"
cat > "$T/pieces.lua" <<LUA
package.path = "$ROOT/tests/lua/?.lua;" .. package.path
local T = require "testlib"
local whole = T.read_pvtu(arg[1]).pieces[1]
local pv = T.read_pvtu(arg[2])
T.check(#pv.pieces == tonumber(arg[3]), "%d pieces, expected %s", #pv.pieces, arg[3])
print(T.same_pieces(whole, pv, 1e-10))
LUA
for n in 2 3 2p 3p; do
  out=$("$LUGAL" "$T/pieces.lua" "$T/1/poisson.pvtu" "$T/$n/poisson.pvtu" ${n%p} 2> "$T/pieces.err") ||
    fail "the .pvtu of $n distributed ranks: $out $(cat "$T/pieces.err")"
  [ "$out" = 1152 ] || fail "the .pvtu of $n distributed ranks: $out cells compared, expected 1152"
done

# more ranks than cells: a 1D mesh of 2 cells on 4 ranks, two of them empty
cat > "$T/tiny.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.interval{n = 2}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dx(u, 1)*lg.dx(v, 1) - v),
                             bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}:solve()
print(string.format("%.15f %d %.15f", uh:eval{{0.5}}[1], uh:ndof(), lg.integrate(mesh, uh)))
LUA
for n in 1 4; do
  out=$(run $n "$T/tiny.lua" 2> "$T/e") || { cat "$T/e"; fail "empty parts ($n ranks)"; }
  [ "$out" = "0.125000000000000 3 0.062500000000000" ] || fail "u(1/2), ndof, integral = $out on $n ranks, expected 1/8, 3, 1/16"
done

# a small generated mesh whose numbering's runs would leave a rank without cells (each cell
# goes with its lowest vertex: box{nx = 2} on 2 ranks gave 48 cells and 0) goes to PTScotch:
# both ranks own cells
cat > "$T/small.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.box{nx = 2}
print(mesh:ncells())
LUA
run 2 "$T/small.lua" -lugal_verbose > /dev/null 2> "$T/e" || { cat "$T/e"; fail "box{nx = 2} on 2 ranks"; }
for r in 0 1; do
  own=$(grep "distribute: rank $r holds" "$T/e" | tr -d '(' | awk '{print $8}')
  [ -n "$own" ] && [ "$own" -ge 12 ] || fail "box{nx = 2} on 2 ranks: rank $r owns '$own' of 48 cells, expected at least 12 $(cat "$T/e")"
done

# what a distributed mesh does not offer yet says so, on every rank
cat > "$T/refuse.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 6}
local P1 = lg.lagrange(1)
local function says(f, ...)
  local ok, err = pcall(f, ...)
  assert(not ok and err:find("distributed mesh", 1, true), tostring(err))
end
-- a reference of other cells is refused (the same message as serially)
local ok, err = pcall(mesh.quality, mesh, "deformation_quality", {reference = lg.mesh.rectangle{nx = 7}})
assert(not ok and err:find("same mesh", 1, true), tostring(err))
-- an SVG of a Lua array of one value per cell of the whole mesh (the same file as serially)
local a = {}
for i = 1, mesh:ncells() do a[i] = math.sin(i) end
mesh:write(arg[1], {a = a})
-- a continuous test function with interior facet terms (its rows take facets beyond the ghosts)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
if lg.size() > 1 then says(function() return lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), u*v) + lg.integral(mesh:interior_facets(), lg.jump(u)*lg.jump(v)),
                                          test = v, unknown = u} end) end
lg.print_all("refused", lg.rank())
LUA
out=$(run 2 "$T/refuse.lua" "$T/cells2.svg" 2> "$T/e") || { cat "$T/e"; fail "refusals on a distributed mesh"; }
[ "$(echo "$out" | grep -c '^refused')" = 2 ] || fail "refusals: $out"
"$LUGAL" "$T/refuse.lua" "$T/cells1.svg" > /dev/null 2>&1
cmp -s "$T/cells1.svg" "$T/cells2.svg" || fail "an SVG of a per-cell Lua array on 2 distributed ranks differs from the serial one"

# an inverted cell in the part of one rank: the run ends with the message and status 1
cat > "$T/tangle.lua" <<'LUA'
local lg = require "lugal"
local verts, cells = {}, {}
for j = 0, 8 do for i = 0, 8 do verts[#verts + 1] = {i / 8, j / 8} end end
for j = 0, 7 do for i = 0, 7 do
  local a = j * 9 + i + 1
  cells[#cells + 1] = {a, a + 1, a + 10}
  cells[#cells + 1] = {a, a + 10, a + 9}
end end
verts[9 * 7 + 8] = {0.7, 0.7} -- pulls vertex (7/8, 7/8) past its neighbour (6/8, 6/8): two inverted cells at the top
local mesh = lg.mesh.new{cell = "triangle", vertices = verts, cells = cells}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) + u*v - v), test = v, unknown = u}:solve()
LUA
start=$(date +%s)
run 2 "$T/tangle.lua" > "$T/o" 2> "$T/e" && fail "a tangled part ran to the end"
grep -q "inverted or zero-size cell" "$T/e" || { cat "$T/e"; fail "the tangled part's message"; }
[ $(( $(date +%s) - start )) -lt 60 ] || fail "the tangled run took more than a minute to end"
# every example, distributed on 2 and 3 ranks (their own checks: rates, Taylor tests,
# reference values, optimized designs)
mkdir -p "$T/ex"
for n in 2 3; do
  for e in ale_vortex boundary_control bratu burgers1d cahn_hilliard coefficient_inversion dg_poisson elasticity gmsh_domain \
           heat hyperelasticity kkt_poisson navier_stokes poisson poisson3d poisson_control poisson_quad stokes topology; do
    (cd "$T/ex" && run $n "$ROOT/examples/$e.lua" > "$T/ex.out" 2>&1) || { tail -n 15 "$T/ex.out"; fail "example $e distributed on $n ranks"; }
  done
done
echo "mpi_dist: distributed meshes on 2 and 3 ranks as the serial run, VTU and .pvtu, empty parts, refusals, a tangled part, 19 examples on 2 and 3 ranks: as expected"

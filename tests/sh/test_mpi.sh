#!/bin/sh
# test_mpi.sh BUILD — the same script on 1, 2 and 3 processes (mpiexec, as root too):
# tests/lua/mpi_cases.lua's quantities (error norms of direct solves to 1e-10 relative;
# iterative solves, Newton and optimization to 1e-8; iteration counts within 1), the
# VTU it writes (rank 0 writes, the same file as the serial run's), the .pvtu (a piece per
# rank, reassembling cell by cell into the serial mesh and field), rows that follow a
# partition of the cells (few ghost columns on a shuffled numbering), a mesh read on rank 0
# and sent to the others, print on rank 0 only,
# lg.rank / lg.size / lg.allreduce, a rank with no rows (more ranks than nodes), and a Lua
# error or a tangled mesh on one rank ending the whole run with its message and status 1
# within seconds, and Lua garbage on one rank not hanging the run; Open MPI's shared-memory
# layer chosen for ranks on one machine unless the user chose one. Meshes whole on every
# rank (-lugal_distribute 0) but for the garbage case, run both ways.
BUILD=$1
. "$(dirname "$0")/mpi_lib.sh"
# the meshes whole on every rank (-lugal_distribute 0; test_mpi_dist.sh runs the default,
# distributed meshes)
# (through PETSC_OPTIONS: after a script with no arguments of its own "0" would be its arg[2])
run() { rn=$1; shift; if [ "$rn" = 1 ]; then "$LUGAL" "$@"; else PETSC_OPTIONS="-lugal_distribute 0" timeout 300 mpiexec -n "$rn" "$LUGAL" "$@"; fi; }

# n = 2p, 3p: the rows by PTScotch's partition of the cells (the generated meshes keep the
# numbering's order by default), every kind of problem with its rows reordered
for n in 1 2 3 2p 3p; do
  mkdir -p "$T/$n"
  case $n in *p) opt="-lugal_partitioner ptscotch" ;; *) opt= ;; esac
  run ${n%p} "$ROOT/tests/lua/mpi_cases.lua" "$T/$n" $opt > "$T/out$n" 2> "$T/err$n" || { cat "$T/err$n"; fail "mpi_cases on $n ranks"; }
done
for n in 2 3 2p 3p; do
  [ "$(wc -l < "$T/out1")" = "$(wc -l < "$T/out$n")" ] || fail "$n ranks printed $(wc -l < "$T/out$n") lines, 1 rank $(wc -l < "$T/out1") (print on rank 0 only)"
  paste "$T/out1" "$T/out$n" | awk -v what="$n ranks" -f "$ROOT/tests/sh/compare_ranks.awk" || exit 1
  # rank 0 wrote it: the serial file's size (the values may differ in their last bits)
  [ -s "$T/$n/poisson.vtu" ] || fail "no VTU written on $n ranks"
  [ "$(wc -c < "$T/1/poisson.vtu")" = "$(wc -c < "$T/$n/poisson.vtu")" ] || fail "the VTU of $n ranks differs in size"
done
# the .pvtu of n ranks: n pieces whose cells (found by their number, the "id" cell value)
# are the serial run's with the same coordinates and values (to the direct solves' 1e-10)
cat > "$T/pieces.lua" <<LUA
package.path = "$ROOT/tests/lua/?.lua;" .. package.path
local T = require "testlib"
local whole = T.read_pvtu(arg[1]).pieces[1]
local pv = T.read_pvtu(arg[2])
T.check(#pv.pieces == tonumber(arg[3]), "%d pieces, expected %s", #pv.pieces, arg[3])
T.check(#pv.pieces[1].cells < #whole.cells, "piece 1 holds %d of %d cells", #pv.pieces[1].cells, #whole.cells)
print(T.same_pieces(whole, pv, 1e-10))
LUA
for n in 2 3 2p 3p; do
  out=$("$LUGAL" "$T/pieces.lua" "$T/1/poisson.pvtu" "$T/$n/poisson.pvtu" ${n%p} 2> "$T/pieces.err") ||
    fail "the .pvtu of $n ranks: $out $(cat "$T/pieces.err")"
  [ "$out" = 1152 ] || fail "the .pvtu of $n ranks: $out cells compared, expected 1152"
  # a minimization's series: a .pvtu of n pieces per iteration
  steps=$(grep -c 'file="opt_[0-9]*.vtu"' "$T/1/opt.pvd")
  [ "$steps" -gt 1 ] && [ "$(grep -c 'file="opt_[0-9]*.pvtu"' "$T/$n/opt.pvd")" = "$steps" ] ||
    fail "lg.minimize's series on $n ranks: $(cat "$T/$n/opt.pvd")"
  [ -s "$T/$n/opt_0000_p$((${n%p} - 1)).vtu" ] || fail "the pieces of a minimization's series on $n ranks"
done

# the rows follow a partition of the cells (PTScotch): on a grid numbered in a shuffled
# order, the other ranks' columns a rank reads are a border's, not most of the mesh as when
# the rows are split in the numbering's order (-lugal_partitioner natural); same solution
"$LUGAL" "$ROOT/tests/lua/mpi_partition.lua" > "$T/part1" 2> "$T/err" || { cat "$T/part1" "$T/err"; fail "mpi_partition serially"; }
for n in 2 3; do
  run $n "$ROOT/tests/lua/mpi_partition.lua" > "$T/part$n" 2> "$T/err" || { cat "$T/part$n" "$T/err"; fail "mpi_partition on $n ranks"; }
  run $n "$ROOT/tests/lua/mpi_partition.lua" -lugal_partitioner natural > "$T/nat$n" 2> "$T/err" ||
    { cat "$T/nat$n" "$T/err"; fail "natural on $n ranks"; }
  for grid in "" "grid "; do
    cat "$T/part1" "$T/part$n" "$T/nat$n" | awk -v n=$n -v p="$grid" '
      substr($0, 1, length(p) + 4) == p "norm" && (p != "" || $1 == "norm") { v[++k] = $NF }
      substr($0, 1, length(p) + 4) == p "rows" && (p != "" || $1 == "rows") { r[++j] = $(NF - 2); g[j] = $NF }
      END { for (i = 2; i <= 3; i++) { d = v[i] - v[1]; if (d < 0) d = -d
              if (k != 3 || d > 1e-10 * v[1]) { print "FAIL: " p "the norm on " n " ranks: " v[i] " against " v[1]; exit 1 } }
            if (r[2] != 4225 || r[3] != 4225) { print "FAIL: " p "rows " r[2] ", " r[3] " of 4225 on " n " ranks"; exit 1 }
            if (!(g[2] > 0 && g[2] * 10 < g[3])) { print "FAIL: " p g[2] " ghost columns partitioned against " g[3] " in the dof order on " n " ranks"; exit 1 }
            printf "%d ranks, %s: %d ghost columns partitioned, %d in the dof order\n", n, p == "" ? "shuffled grid" : "generated grid", g[2], g[3] }' || exit 1
  done
done

# lg.mesh.read on 3 ranks: rank 0 parses, the others receive the same mesh (sizes, a
# checksum of the coordinates and cells equal on every rank, names and tags kept); a file
# that cannot be read gives rank 0's message on every rank
cat > "$T/read.lua" <<LUA
local lg = require "lugal"
local m = lg.mesh.read("$ROOT/examples/domain.msh")
local s = 0
for i = 1, m:nvertices() do local x, y = m:coordinates(i); s = s + i * x + y end
local info = m:info()
local v = {m:nvertices(), m:ncells(), info.boundary_facets, s}
local lo, hi = lg.allreduce(v, "min"), lg.allreduce(v, "max")
for i = 1, #v do assert(lo[i] == hi[i], "entry " .. i .. " differs between the ranks") end
print("read", m:nvertices(), m:ncells(), table.concat(info.boundaries, ","))
local ok, err = pcall(lg.mesh.read, "$T/nonexistent.msh")
lg.print_all("error", lg.rank(), err)
LUA
out=$(run 3 "$T/read.lua" 2> "$T/err") || { cat "$T/err"; fail "lg.mesh.read on 3 ranks: $out"; }
serial=$("$LUGAL" "$T/read.lua" 2> "$T/err" | grep "^read") || fail "lg.mesh.read serially"
[ "$(echo "$out" | grep "^read")" = "$serial" ] || fail "lg.mesh.read on 3 ranks: $out, serially: $serial"
[ "$(echo "$out" | grep -c "^error.*nonexistent.msh: No such file")" = 3 ] || fail "a missing file on 3 ranks: $out"

# rank, size and reductions; print on rank 0 only, lg.print_all on every rank
cat > "$T/ranks.lua" <<'LUA'
local lg = require "lugal"
print("size", lg.size(), "sum", lg.allreduce(lg.rank() + 1), "min", lg.allreduce(lg.rank(), "min"),
      "table", table.concat(lg.allreduce({1, lg.rank()}, "max"), ","))
lg.print_all("rank", lg.rank())
LUA
out=$(run 3 "$T/ranks.lua") || fail "ranks.lua"
echo "$out" | grep -q "^size	3	sum	6	min	0	table	1,2$" || fail "lg.size / lg.allreduce: $out"
[ "$(echo "$out" | grep -c '^rank')" = 3 ] || fail "lg.print_all prints on every rank: $out"
[ "$(echo "$out" | grep -c '^size')" = 1 ] || fail "print prints on rank 0 only: $out"

# more ranks than nodes: a 1D mesh of 2 cells (3 P1 nodes) on 3 ranks... and 4
cat > "$T/tiny.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.interval{n = 2}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dx(u, 1)*lg.dx(v, 1) - v),
                             bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}:solve()
print(string.format("%.15f", uh(0.5)))
LUA
for n in 1 4; do
  out=$(run $n "$T/tiny.lua") || fail "a rank without rows ($n ranks)"
  [ "$out" = "0.125000000000000" ] || fail "u(1/2) = $out on $n ranks, expected 1/8"
done

# a Lua error on rank 1 only: the run ends with its message and status 1, no rank waits
cat > "$T/err.lua" <<'LUA'
local lg = require "lugal"
if lg.rank() == 1 then error("rank one gives up") end
local mesh = lg.mesh.rectangle{nx = 8}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - v),
                  bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}:solve()
LUA
start=$(date +%s)
run 2 "$T/err.lua" > "$T/o" 2> "$T/e"
rc=$?
[ $rc != 0 ] || fail "a Lua error on rank 1 exited 0"
grep -q "rank 1 of 2: .*err.lua:2: rank one gives up" "$T/e" || { cat "$T/e"; fail "the message of rank 1"; }
[ $(( $(date +%s) - start )) -lt 60 ] || fail "the run took more than a minute to end"

# a collective call on one rank only (q:min under `if lg.rank() == 0`, lg.allreduce): the run
# ends at once with a message naming what each rank called, where it hung with no output;
# distributed and with whole meshes (q:min is collective only on distributed ones: there the
# allreduce meets the end of the script)
cat > "$T/coll.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 8}
local q = mesh:quality("mean_ratio")
if lg.rank() == 0 then print(q:min()) end
if lg.rank() == 1 then print(lg.allreduce(1)) end
local uh = lg.interpolate(lg.lagrange(1), mesh, lg.x, "w")
LUA
for opt in "" "-lugal_distribute 0"; do
  start=$(date +%s)
  (cd "$T" && timeout 120 mpiexec -n 2 "$LUGAL" coll.lua $opt > o 2> e) && fail "a collective call on one rank ran through ($opt)"
  case "$opt" in
    "") want="rank 0 is at q:min (collective call #2, coll.lua:4), rank 1 is at lg.allreduce (collective call #2, coll.lua:5)" ;;
    *) want="rank 0 is at lg.interpolate (collective call #2, coll.lua:6), rank 1 is at lg.allreduce (collective call #2, coll.lua:5)" ;;
  esac
  grep -qF "collective calls out of step: $want" "$T/e" || { cat "$T/e"; fail "the message of a collective call on one rank ($opt)"; }
  [ $(( $(date +%s) - start )) -lt 60 ] || fail "a collective call on one rank took more than a minute to end ($opt)"
done
# a call collective only with some arguments (mesh:vertices{near =} on a distributed mesh)
# made on one rank: the other rank, waiting at its next collective call, says so
cat > "$T/near.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 8}
if lg.rank() == 0 then mesh:vertices{near = {0.5, 0.5}} end
lg.integrate(mesh, 1)
LUA
(cd "$T" && timeout 20 mpiexec -n 2 "$LUGAL" near.lua -lugal_collective_wait 2 > o 2> e)
grep -q "rank 1 has waited 2 s at lg.integrate (collective call #2, near.lua:4) for the other ranks" "$T/e" ||
  { cat "$T/e"; fail "no word from a rank waiting at a collective call"; }

# Lua garbage on one rank only: its collector must not destroy a parallel factorization
# (collective) while the other rank waits elsewhere. Parallel runs collect only at points
# every rank passes; with the automatic collector restarted (what the module stops) the
# same script hangs (checked: 60 s timeouts, both modes)
cat > "$T/gc.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 16}
local P1 = lg.lagrange(1)
local s = 0
for k = 1, 12 do
  local u, v = lg.unknown(P1, "u" .. k), lg.test(P1, "v" .. k)
  local prob = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - k*v),
                                 bc = lg.essential_bc(mesh:boundary(), v*u), test = v, unknown = u}
  local uh = prob:solve()
  prob = nil
  if lg.rank() == 1 then local t = {} for i = 1, 200000 do t[i] = {i} end end
  s = s + lg.integrate(mesh, uh)
end
print(string.format("%.12f", s))
LUA
for opt in "-lugal_distribute 0" ""; do
  out=$(timeout 120 mpiexec -n 2 "$LUGAL" "$T/gc.lua" $opt 2> "$T/e") || { tail -n 5 "$T/e"; fail "garbage on one rank ($opt): a hang or an error"; }
  [ "$out" = "$("$LUGAL" "$T/gc.lua")" ] || fail "garbage on one rank ($opt): $out"
done

# an inverted cell: every rank finds it, the run ends with the message
cat > "$T/tangle.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.new{cell = "triangle", vertices = {{0, 0}, {1, 0}, {0, 1}, {1, 1}},
                         cells = {{1, 2, 3}, {2, 3, 4}}, boundary = {all = {{1, 2}, {2, 4}, {4, 3}, {3, 1}}}}
local P1 = lg.lagrange(1)
local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(u), lg.grad(v)) - v),
                  test = v, unknown = u}:solve()
LUA
run 2 "$T/tangle.lua" > "$T/o" 2> "$T/e" && fail "a tangled mesh ran to the end"
grep -q "inverted or zero-size cell" "$T/e" || { cat "$T/e"; fail "the tangled mesh's message"; }
# every example on 2 ranks (their own checks: convergence rates, reference values, Taylor
# rates), the convergence tests on 3
mkdir -p "$T/ex"
for e in "$ROOT"/examples/*.lua; do
  (cd "$T/ex" && run 2 "$e" > "$T/ex.out" 2>&1) || { tail -n 15 "$T/ex.out"; fail "example $(basename "$e") on 2 ranks"; }
done
(cd "$T/ex" && run 3 "$ROOT/tests/lua/test_convergence.lua" > "$T/conv.out" 2>&1) || { tail -n 15 "$T/conv.out"; fail "test_convergence on 3 ranks"; }
# ranks all on this machine take Open MPI's shared-memory layer without probing the others
# (lg_petsc_init sets OMPI_MCA_pml=ob1), unless the user chose a layer
printf 'local lg = require "lugal"\nlg.print_all(os.getenv("OMPI_MCA_pml"))\n' > "$T/pml.lua"
# (stdout only: a sanitizer build prints its suppression counts on stderr)
out=$(env -u OMPI_MCA_pml timeout 60 mpiexec -n 2 "$LUGAL" "$T/pml.lua" 2> "$T/pml.err") || fail "OMPI_MCA_pml: $(cat "$T/pml.err")"
[ "$out" = "ob1
ob1" ] || fail "OMPI_MCA_pml on 2 ranks of one machine: got '$out', expected ob1 on each"
out=$(OMPI_MCA_pml=^cm timeout 60 mpiexec -n 2 "$LUGAL" "$T/pml.lua" 2> "$T/pml.err") || fail "OMPI_MCA_pml=^cm: $(cat "$T/pml.err")"
[ "$out" = "^cm
^cm" ] || fail "the user's OMPI_MCA_pml: got '$out'"

echo "mpi: ranks, reductions, empty ranks, errors on one rank, every example on 2 ranks, convergence on 3: as expected"

#!/bin/sh
# test_mpi_read.sh BUILD — a Gmsh file read in parallel (read_dist.c): each rank reads its
# run of the file's nodes and elements, no rank the whole file. tests/lua/mpi_read.lua's
# quantities on 2 and 3 ranks against the serial run (MSH 4.1 and 2.2 files; a file with
# its nodes in reverse order, an unused node, a tagged point, cells repeated under another
# physical group, tagged interior facets, a facet tagged twice and one repeated; a
# clockwise file, which is reversed); with the numbering's runs as the partition the parts
# are those rank 0 cuts from the whole mesh, to the byte (the .pvtu pieces compared with
# cmp against -lugal_read_parts 0); a file whose layout the parallel path does not take
# (two nodes on a line) read whole by rank 0, with the same answers; generated meshes that
# PTScotch partitions on 4 ranks made and partitioned rank by rank; the hostile corpus on 2
# ranks as serially; a bad file ending the run with the whole reader's message and line.
BUILD=$1
. "$(dirname "$0")/mpi_lib.sh"
run() { rn=$1; shift; if [ "$rn" = 1 ]; then "$LUGAL" "$@"; else timeout 300 mpiexec -n "$rn" "$LUGAL" "$@"; fi; }

# the generated variants of a 16 x 16 rectangle written by lugal (MSH 2.2)
cat > "$T/gen.lua" <<'LUA'
local lg = require "lugal"
lg.mesh.rectangle{nx = 16}:write(arg[1])
LUA
"$LUGAL" "$T/gen.lua" "$T/base.msh" || fail "writing the base mesh"
awk -v dir="$T" '
  /^\$Nodes/ { sec = "n"; print > (dir "/dup.msh"); next }
  /^\$EndNodes/ { sec = ""; for (i = nn; i >= 1; i--) print node[i] > (dir "/dup.msh"); print "9999 5 5 0" > (dir "/dup.msh") }
  /^\$Elements/ { sec = "e"; print > (dir "/dup.msh"); next }
  /^\$EndElements/ { sec = "" }
  sec == "n" { if (!cnt) { cnt = 1; print $1 + 1 > (dir "/dup.msh") } else node[++nn] = $0; next }
  sec == "e" {
    if (!ecnt) { ecnt = 1; ne = $1; next }
    el[++m] = $0; next }
  { if ($0 == "$EndElements") {
      # the elements, some cells twice (the second in physical group 5), 16 interior facets
      # on y = 1/2 tagged 77, a boundary facet twice under its tag and once under 9, a point
      extra = 0
      for (i = 1; i <= m; i++) { split(el[i], f, " "); if (f[2] == 2 && f[1] % 7 == 0) extra++ }
      print ne + extra + 16 + 3 > (dir "/dup.msh")
      id = 100000
      for (i = 1; i <= m; i++) {
        print el[i] > (dir "/dup.msh"); split(el[i], f, " ")
        if (f[2] == 2 && f[1] % 7 == 0) print ++id, 2, 2, 5, 1, f[6], f[7], f[8] > (dir "/dup.msh")
        if (i == 1) { print ++id, 1, 2, f[4], f[5], f[6], f[7] > (dir "/dup.msh"); print ++id, 1, 2, 9, 9, f[6], f[7] > (dir "/dup.msh") }
      }
      for (i = 0; i < 16; i++) print ++id, 1, 2, 77, 7, 8 * 17 + i + 1, 8 * 17 + i + 2 > (dir "/dup.msh")
      print ++id, 15, 2, 3, 3, 1 > (dir "/dup.msh")
    }
    print > (dir "/dup.msh") }' "$T/base.msh"
# clockwise: every triangle's last two nodes swapped
awk '/^\$Elements/ { e = 1 } e && NF == 8 && $2 == 2 { t = $8; $8 = $7; $7 = t } { print }' "$T/base.msh" > "$T/cw.msh"
# two nodes on one line: the whole reader takes it, the parallel layout does not
awk '/^\$Nodes/ { n = 1; print; next } n == 2 { printf "%s ", $0; n = 3; next } n == 1 { n = 2 } { print }' "$T/base.msh" > "$T/tokens.msh"
FILES="$ROOT/tests/data/square_unstructured.msh $ROOT/tests/data/cube_unstructured.msh $ROOT/examples/domain.msh $T/dup.msh $T/cw.msh $T/tokens.msh $ROOT/tests/data/hostile/mesh/partitioned_square.msh"

run 1 "$ROOT/tests/lua/mpi_read.lua" $FILES > "$T/out1" 2> "$T/err1" || { cat "$T/err1"; fail "mpi_read serially"; }
grep -q "^dup_region_5 " "$T/out1" || fail "the repeated cells' physical group 5 is not a region: $(grep dup "$T/out1")"
grep -q "^dup_boundary_77 " "$T/out1" || fail "the interior facets' tag 77 is not a boundary"
# gmsh -part 2 of the same square: its partition interface is no boundary (it was read as
# a boundary named "5", and the Poisson solve fixed u = 0 there too)
[ "$(grep -c "^partitioned_square_boundary_[a-z]* direct" "$T/out1")" = 4 ] || fail "the partitioned square's boundaries: $(grep partitioned_square_boundary "$T/out1")"
awk '$1 == "square_unstructured_poisson" { a = $3 } $1 == "partitioned_square_poisson" { b = $3 }
     END { d = a - b; if (d < 0) d = -d; if (!(a > 0) || d > 1e-12 * a) { print "FAIL: the partitioned square solves to " b ", the whole one to " a; exit 1 } }' "$T/out1" || exit 1
for n in 2 3 2n 3n; do
  case $n in *n) opt="-lugal_partitioner natural" ;; *) opt= ;; esac
  run ${n%n} "$ROOT/tests/lua/mpi_read.lua" $FILES $opt -lugal_verbose > "$T/out$n" 2> "$T/err$n" ||
    { tail -n 20 "$T/err$n"; fail "mpi_read on $n ranks"; }
  [ "$(wc -l < "$T/out1")" = "$(wc -l < "$T/out$n")" ] || fail "$n ranks printed $(wc -l < "$T/out$n") lines, 1 rank $(wc -l < "$T/out1")"
  paste "$T/out1" "$T/out$n" | awk -v what="$n ranks reading in parallel" -f "$ROOT/tests/sh/compare_ranks.awk" || exit 1
  # every file but tokens.msh read rank by rank (6 files), each rank its run; tokens.msh by rank 0
  here=$(grep -c "distribute: rank [0-9]* holds .* read here" "$T/err$n")
  [ "$here" = $((6 * ${n%n})) ] || fail "$n ranks: $here reports of a part read here, expected $((6 * ${n%n})) $(grep read "$T/err$n")"
  grep -q "read: .*tokens.msh read whole by rank 0" "$T/err$n" || fail "$n ranks: tokens.msh not read whole by rank 0"
done
# the numbering's runs: the same parts as rank 0 cuts, to the byte
cat > "$T/pieces.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.read(arg[1])
local f = lg.interpolate(lg.lagrange(1), mesh, lg.sin(3*lg.x + lg.y))
mesh:write(arg[2], {f = f, q = mesh:quality("mean_ratio")})
LUA
for case in "cube_unstructured.msh 1" "dup.msh 1" "cw.msh 1" "dup.msh 2"; do
  set -- $case
  f=$T/$1
  [ -f "$f" ] || f=$ROOT/tests/data/$1
  for rp in 1 0; do
    mkdir -p "$T/p$rp"
    run 3 "$T/pieces.lua" "$f" "$T/p$rp/o.pvtu" -lugal_partitioner natural -lugal_ghost_layers $2 -lugal_read_parts $rp -lugal_verbose \
      > /dev/null 2> "$T/e$rp" || { cat "$T/e$rp"; fail "pieces of $f"; }
    # each rank's cells, owned cells, ghosts and vertices
    grep -o "distribute: rank [0-9]* holds [0-9]* cells ([0-9]* owned, [0-9]* ghosts) and [0-9]* vertices" "$T/e$rp" | sort > "$T/held$rp"
  done
  [ "$(wc -l < "$T/held1")" = 3 ] && cmp -s "$T/held1" "$T/held0" ||
    fail "$1, $2 ghost layers: the parts read in parallel hold $(cat "$T/held1"), those rank 0 cut $(cat "$T/held0")"
  for p in o.pvtu o_p0.vtu o_p1.vtu o_p2.vtu; do
    cmp -s "$T/p1/$p" "$T/p0/$p" || fail "$1, $2 ghost layers: piece $p read in parallel differs from the one rank 0 cut"
  done
done
# generated meshes partitioned by PTScotch on 4 ranks: each rank generates its window and the
# ranks partition the vertex graph together (no whole mesh on rank 0); the serial answers
cat > "$T/gen4.lua" <<'LUA'
local lg = require "lugal"
local x, y, z = lg.x, lg.y, lg.z
for _, mesh in ipairs{lg.mesh.box{nx = 10}, lg.mesh.rectangle{nx = 40, cell = "quadrilateral"}} do
  local P1 = lg.lagrange(1)
  local u, v = lg.unknown(P1, "u"), lg.test(P1, "v")
  local uh = lg.linear_problem{mesh = mesh, eqn = lg.integral(mesh:cells(), lg.dot(lg.grad(v), lg.grad(u)) - (1 + x)*v),
                               bc = lg.essential_bc(mesh:boundary("left", "right"), v*u), test = v, unknown = u}:solve()
  print(string.format("gen%d_poisson direct %.17g", mesh:info().dim, lg.integrate(mesh, uh*uh)))
  print(string.format("gen%d_top direct %.17g", mesh:info().dim, lg.integrate(mesh:boundary("top"), uh + 1)))
  print(string.format("gen%d_ndof count %d", mesh:info().dim, uh:ndof()))
end
LUA
run 1 "$T/gen4.lua" > "$T/g1" 2> "$T/e" || { cat "$T/e"; fail "generated meshes serially"; }
run 4 "$T/gen4.lua" -lugal_partitioner ptscotch -lugal_verbose > "$T/g4" 2> "$T/e" || { tail -n 20 "$T/e"; fail "generated meshes on 4 ranks"; }
paste "$T/g1" "$T/g4" | awk -v what="4 ranks, generated meshes partitioned on every rank" -f "$ROOT/tests/sh/compare_ranks.awk" || exit 1
[ "$(grep -c "generated here and partitioned on every rank" "$T/e")" = 8 ] ||
  fail "4 ranks: the generated meshes not partitioned on every rank: $(grep distribute "$T/e")"

# the hostile corpus (tests/data/hostile/mesh): every file on 2 ranks, read in parts even when
# tiny (-lugal_read_parts_min 0), accepted or refused as serially, with the same cells,
# vertices, boundary facets and names, or the same message
cat > "$T/hostile.lua" <<'LUA'
local lg = require "lugal"
for i = 1, #arg do
  local f = arg[i]
  if f:match("%.msh$") then
    local ok, m = pcall(lg.mesh.read, f)
    local name = f:match("[^/]+$")
    if ok then
      local info = m:info()
      print(name, "ok", m:ncells(), info.vertices, info.boundary_facets, table.concat(info.boundaries, ","))
    else
      print(name, "error", (tostring(m):gsub("^.-lg%.mesh%.read: ", "")))
    end
  end
end
LUA
run 1 "$T/hostile.lua" "$ROOT"/tests/data/hostile/mesh/*.msh > "$T/h1" 2> "$T/e" || { cat "$T/e"; fail "the hostile corpus serially"; }
run 2 "$T/hostile.lua" "$ROOT"/tests/data/hostile/mesh/*.msh -lugal_read_parts_min 0 -lugal_verbose > "$T/h2" 2> "$T/e" ||
  { tail -n 20 "$T/e"; fail "the hostile corpus on 2 ranks"; }
cmp -s "$T/h1" "$T/h2" || fail "the hostile corpus on 2 ranks: $(diff -a "$T/h1" "$T/h2" | head -n 5)"
parts=$(grep -ac "distribute: rank 0 holds .* read here" "$T/e")
[ "$parts" -ge 15 ] || fail "the hostile corpus: only $parts files read in parts"

# the reader's options in a serial run (a script written for mpiexec): taken, not reported unused
run 1 "$T/hostile.lua" "$ROOT/examples/domain.msh" -lugal_read_parts 0 -lugal_read_parts_min 3 > /dev/null 2> "$T/e" ||
  { cat "$T/e"; fail "the reader's options serially"; }
! grep -q "was not used" "$T/e" || fail "the reader's options reported unused serially: $(cat "$T/e")"

# a bad file: the whole reader's message, with its line, and a failed run
awk '/^\$Elements/ { e = 1 } e && NF == 8 && $2 == 2 && !done { $8 = 9000; done = 1; id = $1 } { print } END { print id > "/dev/stderr" }' \
  "$T/base.msh" > "$T/bad.msh" 2> "$T/badid"
grep -q " 9000$" "$T/bad.msh" || fail "the bad file was not made"
cat > "$T/bad.lua" <<'LUA'
local lg = require "lugal"
lg.mesh.read(arg[1])
LUA
if run 2 "$T/bad.lua" "$T/bad.msh" > "$T/o" 2> "$T/e"; then fail "a bad file read on 2 ranks"; fi
grep -q "bad.msh:[0-9]*: element $(cat "$T/badid") refers to node 9000, which is not in \$Nodes" "$T/e" || fail "bad file: $(cat "$T/e")"

# /dev/zero on 2 ranks: refused after its first 4 KB (it was read for 2 GiB)
if run 2 "$T/bad.lua" /dev/zero > "$T/o" 2> "$T/e"; then fail "/dev/zero read on 2 ranks"; fi
grep -q "/dev/zero: it does not start like a Gmsh MSH file" "$T/e" || fail "/dev/zero on 2 ranks: $(head -n 3 "$T/e")"

# a partitioner this PETSc lacks (or a typo), on a parallel read and on a generated mesh on 4
# ranks: the run ends with a message naming the partitioners there are (it aborted with
# "double free or corruption": the graph's arrays were freed twice)
printf 'local lg = require "lugal"\nlg.mesh.rectangle{nx = 16}\n' > "$T/gen16.lua"
for p in parmetis chaco typo; do
  if run 2 "$T/bad.lua" "$ROOT/tests/data/square_unstructured.msh" -lugal_partitioner $p > "$T/o" 2> "$T/e"; then fail "-lugal_partitioner $p accepted"; fi
  grep -q "lugal_partitioner $p: this PETSc has no such partitioner (it has .*ptscotch" "$T/e" || fail "-lugal_partitioner $p: $(head -n 3 "$T/e")"
  ! grep -q "double free\|signal" "$T/e" || fail "-lugal_partitioner $p crashed: $(head -n 3 "$T/e")"
done
if run 4 "$T/gen16.lua" -lugal_partitioner parmetis > "$T/o" 2> "$T/e"; then fail "-lugal_partitioner parmetis accepted on 4 ranks"; fi
grep -q "no such partitioner" "$T/e" && ! grep -q "double free\|signal" "$T/e" || fail "-lugal_partitioner parmetis on 4 ranks: $(head -n 3 "$T/e")"
echo "ok"

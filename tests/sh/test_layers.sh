#!/bin/sh
# test_layers.sh BUILD — the arrows of docs/architecture.md: every room uses only the rooms
# below it. Checked twice: the #include lines of src/ (a quoted include resolved to its
# room; the bottom rooms include no PETSc, MPI, Lua or libtcc header), and the symbols of
# the built objects (each undefined symbol of a room's objects is defined by that room or a
# room below it, or outside lugal; the bottom rooms reference no PETSc, MPI, Lua or libtcc
# symbol). A violation names the file and the include or symbol.
BUILD=$1
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
cd "$ROOT" || exit 1
# room: the rooms it may use (itself first). The order, lowest first, is docs/architecture.md's
cat > "$T/rooms" <<'EOF'
mesh mesh
mesh/io mesh/io mesh
mesh/quality mesh/quality mesh
mesh/untangle mesh/untangle mesh/quality mesh
mesh/tool mesh/tool mesh/untangle mesh/quality mesh/io mesh
expr expr
assemble/fem assemble/fem mesh
assemble/kernel assemble/kernel assemble/fem mesh/io mesh expr
assemble/process assemble/process assemble/kernel assemble/fem mesh expr
assemble/parallel assemble/parallel assemble/process assemble/kernel assemble/fem mesh/io mesh/quality mesh expr
assemble assemble assemble/parallel assemble/process assemble/kernel assemble/fem mesh/io mesh/quality mesh/untangle mesh expr
assemble/problem assemble/problem assemble assemble/parallel assemble/process assemble/kernel assemble/fem mesh/io mesh/quality mesh/untangle mesh expr
assemble/optimize assemble/optimize assemble/problem assemble assemble/parallel assemble/process assemble/kernel assemble/fem mesh/io mesh/quality mesh/untangle mesh expr
lua lua assemble/optimize assemble/problem assemble assemble/parallel assemble/process assemble/kernel assemble/fem mesh/io mesh/quality mesh/untangle mesh expr
EOF
fails=0
# 1. includes
for f in src/*/*.c src/*/*.h src/*/*/*.c src/*/*/*.h; do
  [ -f "$f" ] || continue
  room=$(dirname "${f#src/}")
  allowed=$(awk -v r="$room" '$1 == r { $1 = ""; print }' "$T/rooms")
  [ -n "$allowed" ] || { echo "FAIL: $f is in a room docs/architecture.md does not list ($room)"; fails=$((fails + 1)); continue; }
  dir=$(dirname "$f")
  grep -n '^[[:space:]]*#[[:space:]]*include[[:space:]]*"' "$f" | sed 's/^\([0-9]*\):.*"\(.*\)".*/\1 \2/' | while read -r line inc; do
    target=$(cd "$dir" && realpath -m "$inc")
    case "$target" in
      "$ROOT/src/config.h") continue ;;
      "$ROOT"/src/*) troom=$(dirname "${target#$ROOT/src/}") ;;
      *) echo "FAIL: $f:$line includes \"$inc\", outside src/"; echo x >> "$T/bad"; continue ;;
    esac
    case " $allowed " in
      *" $troom "*) ;;
      *) echo "FAIL: $f:$line includes \"$inc\": room $room may use only$allowed"; echo x >> "$T/bad" ;;
    esac
  done
  case "$room" in
    mesh* | expr | assemble/fem)
      if grep -n '^[[:space:]]*#[[:space:]]*include[[:space:]]*<\(petsc\|mpi\|lua\|lauxlib\|lualib\|libtcc\)' "$f"; then
        echo "FAIL: $f includes a PETSc, MPI, Lua or libtcc header: src/$room uses libc, libm and OpenMP only"; fails=$((fails + 1))
      fi ;;
    assemble/kernel)
      if grep -n '^[[:space:]]*#[[:space:]]*include[[:space:]]*<\(petsc\|mpi\|lua\|lauxlib\|lualib\)' "$f"; then
        echo "FAIL: $f includes a PETSc, MPI or Lua header: kernels are generated and compiled without them"; fails=$((fails + 1))
      fi ;;
  esac
done
[ -f "$T/bad" ] && fails=$((fails + $(wc -l < "$T/bad")))
# 2. symbols of the built objects (the default build's, where the sources were built)
if [ -d "$BUILD/src/mesh" ]; then
  ROOMS=$(awk '{ print $1 }' "$T/rooms")
  # a room's objects: those of its sources (a build folder may hold objects of files moved since)
  objs() { for o in "$BUILD/src/$1"/*.o; do [ -f "src/$1/$(basename "$o" .o).c" ] && echo "$o"; done; }
  for room in $ROOMS; do
    nm --defined-only $(objs "$room") 2> /dev/null | awk 'NF == 3 && $2 ~ /[TDBRC]/ { print $3 }' | sort -u > "$T/def.$(echo $room | tr / _)"
  done
  while read -r room allowed; do
    r=$(echo "$room" | tr / _)
    nm -u $(objs "$room") 2> /dev/null | awk 'NF == 2 { print $2 }' | sort -u > "$T/und.$r"
    for other in $ROOMS; do
      case " $room $allowed " in *" $other "*) continue ;; esac
      comm -12 "$T/und.$r" "$T/def.$(echo $other | tr / _)" > "$T/up"
      if [ -s "$T/up" ]; then
        echo "FAIL: src/$room's objects call up into src/$other: $(head -n 5 "$T/up" | tr '\n' ' ')"
        fails=$((fails + 1))
      fi
    done
    case "$room" in
      mesh* | expr | assemble/fem | assemble/kernel)
        pat='^(Petsc|PETSC|Mat[A-Z]|Vec[A-Z]|KSP|SNES|Tao|PC[A-Z]|MPI_|PMPI_|ompi_|lua_|luaL_|tcc_)'
        [ "$room" = assemble/kernel ] && pat='^(Petsc|PETSC|Mat[A-Z]|Vec[A-Z]|KSP|SNES|Tao|PC[A-Z]|MPI_|PMPI_|ompi_|lua_|luaL_)'
        grep -E "$pat" "$T/und.$r" > "$T/ext"
        if [ -s "$T/ext" ]; then
          echo "FAIL: src/$room's objects reference $(head -n 5 "$T/ext" | tr '\n' ' '): it uses libc, libm and OpenMP only"
          fails=$((fails + 1))
        fi ;;
    esac
  done < "$T/rooms"
else
  echo "FAIL: no objects in $BUILD/src/mesh (build first)"; fails=$((fails + 1))
fi
[ "$fails" -eq 0 ] || exit 1
echo "layers: every include and every symbol reference goes down (mesh < mesh/io, mesh/quality < mesh/untangle < mesh/tool; mesh, expr < assemble/fem < kernel < process < parallel < assemble < problem < optimize < lua)"

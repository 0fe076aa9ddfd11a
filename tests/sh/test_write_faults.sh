#!/bin/sh
# test_write_faults.sh BUILD — what a failed or interrupted write leaves: on a full file
# system (a 192 KiB tmpfs, where root may mount one; else a file size limit) a series step
# or a .pvtu that does not fit fails with the reason, the earlier steps, the .pvd and an
# earlier .pvtu of the same name with its pieces stay whole, and no temporary file remains
# (ENOSPC at piece 2 left new pieces 0-1 beside old pieces 2-3); ulimit -f gives "File too
# large" (the run died of SIGXFSZ with no message); SIGTERM and SIGINT during a write leave
# no temporary file (20-30 MB *.tmpPID.N files were left); a rewritten chmod 600 file stays
# 600, a symbolic link is written through (the link stays, its file changes), and a 249-byte
# file name can be written (the temporary name was too long for it).
BUILD=$1
LUGAL=$BUILD/lugal
T=$(mktemp -d)
M=$T/full
cleanup() { umount "$M" 2> /dev/null; rm -rf "$T"; }
trap cleanup EXIT
fail() { echo "FAIL: $*"; exit 1; }
leftovers() { find "$1" -name '.lugal*.tmp' -o -name '*.tmp[0-9]*' | head -n 3; }
mkdir -p "$M"
if [ "$(id -u)" = 0 ] && mount -t tmpfs -o size=192k tmpfs "$M" 2> /dev/null; then
  limit=""; what="a full 192 KiB file system"; reason="No space left on device"
else
  limit="ulimit -f 160;"; what="a 160 KiB file size limit"; reason="File too large"
fi
cat > "$T/series.lua" <<'LUA'
local lg = require "lugal"
local s = lg.series(arg[1] .. "/run.pvd")
for k = 1, 40 do
  local mesh = lg.mesh.rectangle{nx = 4 + 4*k}
  local ok, err = pcall(s.write, s, mesh, {q = mesh:quality("mean_ratio")}, k)
  if not ok then print("failed at step " .. k .. ": " .. err) return end
end
LUA
out=$(sh -c "$limit \"$LUGAL\" \"$T/series.lua\" \"$M\"" 2>&1) || fail "the series script: $out"
echo "$out" | grep -q "failed at step [0-9]*: .*$reason" || fail "a series step on $what: $out"
[ -z "$(leftovers "$M")" ] || fail "temporary files left on $what: $(leftovers "$M")"
# every step the .pvd names is there and whole
grep -o 'file="[^"]*"' "$M/run.pvd" | sed 's/file="//; s/"$//' > "$T/steps"
[ -s "$T/steps" ] || fail "the .pvd names no step"
while read -r f; do tail -c 12 "$M/$f" | grep -q "</VTKFile>" || fail "step file $f is not whole"; done < "$T/steps"
[ "$(ls "$M" | grep -c '^run_.*\.vtu$')" = "$(wc -l < "$T/steps")" ] || fail "step files not in the .pvd: $(ls "$M")"
rm -f "$M"/*

# a .pvtu of 4 pieces, then a larger one under the same name that does not fit
cat > "$T/pvtu.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = tonumber(arg[2])}
mesh:write(arg[1] .. "/set.pvtu", {q = mesh:quality("mean_ratio")}, {pieces = 4, format = "ascii"})
LUA
sh -c "$limit \"$LUGAL\" \"$T/pvtu.lua\" \"$M\" 8" > "$T/o" 2>&1 || fail "the first .pvtu: $(cat "$T/o")"
sum() { (cd "$M" && cat set.pvtu set_p0.vtu set_p1.vtu set_p2.vtu set_p3.vtu | cksum); }
before=$(sum)
sh -c "$limit \"$LUGAL\" \"$T/pvtu.lua\" \"$M\" 60" > "$T/o" 2>&1 && fail "a .pvtu larger than $what was written"
grep -q "$reason" "$T/o" || fail "the .pvtu's failure: $(cat "$T/o")"
[ "$(sum)" = "$before" ] || fail "the earlier .pvtu and its pieces changed"
[ -z "$(leftovers "$M")" ] || fail "temporary files left by the .pvtu: $(leftovers "$M")"
umount "$M" 2> /dev/null

# a file size limit: the reason, not a death by SIGXFSZ
cat > "$T/big.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 100}
mesh:write(arg[1], {q = mesh:quality("mean_ratio")})
LUA
out=$(sh -c "ulimit -f 10; \"$LUGAL\" \"$T/big.lua\" \"$T/big.vtu\"" 2>&1)
echo "$out" | grep -q "mesh:write: error writing .*big.vtu: File too large" || fail "ulimit -f: $out"
[ -z "$(leftovers "$T")" ] || fail "temporary files left by ulimit -f: $(leftovers "$T")"

# SIGTERM and SIGINT in the middle of writes: no temporary file left
cat > "$T/loop.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = 300}
local q = mesh:quality("mean_ratio")
io.stderr:write("writing\n")
local t0 = os.time()
while os.time() - t0 < 60 do mesh:write(arg[1] .. "/loop.vtu", {q = q}, {format = "ascii"}) end
LUA
for sig in TERM INT; do
  mkdir -p "$T/sig$sig"
  # (a background job of a script starts with SIGINT ignored: given back its default here)
  env --default-signal=INT "$LUGAL" "$T/loop.lua" "$T/sig$sig" 2> "$T/e" &
  pid=$!
  # killed once a first file is whole (a loaded machine may take a while), during later writes
  n=0; while [ ! -s "$T/sig$sig/loop.vtu" ] && [ $n -lt 600 ]; do sleep 0.1; n=$((n + 1)); done
  sleep 0.3
  kill -$sig $pid
  wait $pid
  [ -z "$(leftovers "$T/sig$sig")" ] || fail "SIG$sig left temporary files: $(leftovers "$T/sig$sig")"
  [ -s "$T/sig$sig/loop.vtu" ] || fail "SIG$sig: no whole file from the earlier writes"
  tail -c 12 "$T/sig$sig/loop.vtu" | grep -q "</VTKFile>" || fail "SIG$sig: the earlier file is not whole"
done

# permissions kept, links written through, long names
cat > "$T/small.lua" <<'LUA'
local lg = require "lugal"
local mesh = lg.mesh.rectangle{nx = tonumber(arg[2])}
mesh:write(arg[1], {q = mesh:quality("mean_ratio")}, {format = "ascii"})
LUA
"$LUGAL" "$T/small.lua" "$T/private.vtu" 2 && chmod 600 "$T/private.vtu" && "$LUGAL" "$T/small.lua" "$T/private.vtu" 3 ||
  fail "writing private.vtu"
[ "$(stat -c %a "$T/private.vtu")" = 600 ] || fail "a chmod 600 file rewritten is $(stat -c %a "$T/private.vtu")"
mkdir -p "$T/run42"
"$LUGAL" "$T/small.lua" "$T/run42/out.vtu" 2 && ln -s run42/out.vtu "$T/latest.vtu" && "$LUGAL" "$T/small.lua" "$T/latest.vtu" 3 ||
  fail "writing through a link"
[ -L "$T/latest.vtu" ] || fail "the link was replaced by a file"
grep -q 'NumberOfCells="18"' "$T/run42/out.vtu" || fail "the link's file was not rewritten"
long=$(printf '%0245d' 0 | tr 0 a).vtu
"$LUGAL" "$T/small.lua" "$T/$long" 2 > "$T/o" 2>&1 || fail "a 249-byte file name: $(cat "$T/o")"
[ -s "$T/$long" ] || fail "the 249-byte name was not written"
echo "write faults ($what): earlier files whole, no temporary files, reasons given"

#!/bin/sh
# test_closed_pipe.sh BUILD — output into a closed pipe (lugal script.lua | head) ends the
# run quietly: SIGPIPE's default action (status 141), nothing on stderr (it used to print
# PETSc's 14-line signal report and an MPI_ABORT).
BUILD=$1
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
printf 'local lg = require "lugal"\nfor i = 1, 200000 do print(i) end\n' > "$T/many.lua"
{ "$BUILD/lugal" "$T/many.lua" 2> "$T/err"; echo $? > "$T/rc"; } | head -n 1 > "$T/out"
rc=$(cat "$T/rc")
if [ "$(cat "$T/out")" != "1" ]; then echo "FAIL: first line is '$(cat "$T/out")'"; exit 1; fi
if [ -s "$T/err" ]; then echo "FAIL: stderr is not empty:"; head -n 5 "$T/err"; exit 1; fi
if [ "$rc" != 141 ]; then echo "FAIL: exit status $rc, expected 141 (SIGPIPE)"; exit 1; fi
echo "closed pipe: status 141, stderr empty"

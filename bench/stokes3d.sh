#!/bin/sh
# bench/stokes3d.sh [rounds] [N] — the saddle point default as a user gets it (issue 56): the
# Taylor–Hood channel of bench/stokes3d.lua (N = 10: 29 114 unknowns) with lugal's defaults,
# with OMP_NUM_THREADS=1 and with the former default, the direct solver (-lugal_iterative 0);
# quiet, then beside one busy process; rounds alternating, every line printed, whole
# process times.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
. "$ROOT/bench/busy.sh"
rounds=${1:-3}
N=${2:-10}
for load in quiet busy; do
  [ $load = busy ] && busy_start
  echo "$load: /proc/loadavg $(cat /proc/loadavg)"
  r=1
  while [ "$r" -le "$rounds" ]; do
    for mode in default one_thread direct; do
      case $mode in
        default) env="" opts="" ;;
        one_thread) env="OMP_NUM_THREADS=1" opts="" ;;
        direct) env="" opts="-lugal_iterative 0" ;;
      esac
      # shellcheck disable=SC2086
      env $env /usr/bin/time -f "whole_s=%e rss_kb=%M" "$ROOT/build/lugal" "$ROOT/bench/stokes3d.lua" "$N" $opts 2>&1 |
        tr '\n' ' ' | sed "s/^/$load $mode /"
      echo
    done
    r=$((r + 1))
  done
  busy_stop
done
echo "/proc/loadavg $(cat /proc/loadavg)"

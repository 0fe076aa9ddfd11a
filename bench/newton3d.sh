#!/bin/sh
# bench/newton3d.sh [rounds] [n] — Newton's default linear solver as a user gets it (issue 56):
# the Neo-Hookean beam of bench/newton3d.lua (n = 12: 30 927 unknowns), solve and gradient,
# with lugal's defaults, with OMP_NUM_THREADS=1, hand-tuned (-ksp_type cg -pc_type gamg -ksp_rtol 1e-8) and
# the former default, the direct solver (-lugal_iterative 0); quiet, then beside one busy
# process; rounds alternating, every line printed, whole process times.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
. "$ROOT/bench/busy.sh"
rounds=${1:-3}
n=${2:-12}
for load in quiet busy; do
  [ $load = busy ] && busy_start
  echo "$load: /proc/loadavg $(cat /proc/loadavg)"
  r=1
  while [ "$r" -le "$rounds" ]; do
    for mode in default one_thread tuned direct; do
      case $mode in
        default) env="" opts="" ;;
        one_thread) env="OMP_NUM_THREADS=1" opts="" ;;
        tuned) env="" opts="-ksp_type cg -pc_type gamg -ksp_rtol 1e-8" ;;
        direct) env="" opts="-lugal_iterative 0" ;;
      esac
      # shellcheck disable=SC2086
      env $env /usr/bin/time -f "whole_s=%e rss_kb=%M" "$ROOT/build/lugal" "$ROOT/bench/newton3d.lua" "$n" 0 $opts 2>&1 |
        tr '\n' ' ' | sed "s/^/$load $mode /"
      echo
    done
    r=$((r + 1))
  done
  busy_stop
done
echo "/proc/loadavg $(cat /proc/loadavg)"

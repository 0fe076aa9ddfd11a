#!/bin/sh
# bench/solver_case.sh newton|stokes|navier|elasticity|convection|neumann|rigid|cavity [rounds] [size] — a default solver as a user gets it
# (issue 56), whole process times, rounds alternating, every line printed; quiet, then beside
# one busy process:
#   newton: the Neo-Hookean beam of bench/newton3d.lua (size 12: 30 927 unknowns), solve and
#           gradient, lugal's defaults, OMP_NUM_THREADS=1, hand-tuned (-ksp_type cg -pc_type
#           gamg -ksp_rtol 1e-8) and the former default, the direct solver (-lugal_iterative 0);
#   stokes: the Taylor–Hood channel of bench/stokes3d.lua (size 10: 29 114 unknowns), the
#           same without the hand-tuned run;
#   navier: the same channel at Re = 20 (Navier–Stokes, Newton), solve and gradient;
#   elasticity: vector P1 linear elasticity of bench/elasticity3d.lua (size 24: 46 875
#           unknowns), with the hand-tuned run;
#   convection: convection-diffusion of bench/convection3d.lua (size 28, b = 5: 24 389
#           unknowns), solve and gradient;
#   neumann, rigid, cavity: the null space problems of bench/nullspace3d.lua (sizes 48, 24,
#           10: 117 649, 46 875 and 29 114 unknowns), solve and gradient.
ROOT=$(cd "$(dirname "$0")/.." && pwd)
. "$ROOT/bench/busy.sh"
case ${1:-} in
  newton) script=newton3d.lua size=${3:-12} extra=0 modes="default one_thread tuned direct" ;;
  stokes) script=stokes3d.lua size=${3:-10} extra= modes="default one_thread direct" ;;
  navier) script=stokes3d.lua size=${3:-10} extra=20 modes="default one_thread direct" ;;
  elasticity) script=elasticity3d.lua size=${3:-24} extra= modes="default one_thread tuned direct" ;;
  convection) script=convection3d.lua size=${3:-28} extra=5 modes="default one_thread direct" ;;
  neumann) script=nullspace3d.lua size=${3:-48} extra=neumann modes="default one_thread direct" ;;
  rigid) script=nullspace3d.lua size=${3:-24} extra=rigid modes="default one_thread direct" ;;
  cavity) script=nullspace3d.lua size=${3:-10} extra=cavity modes="default one_thread direct" ;;
  *) echo "usage: sh bench/solver_case.sh newton|stokes|navier|elasticity|convection|neumann|rigid|cavity [rounds] [size]" >&2; exit 2 ;;
esac
rounds=${2:-3}
for load in quiet busy; do
  [ $load = busy ] && busy_start
  echo "$load: /proc/loadavg $(cat /proc/loadavg)"
  r=1
  while [ "$r" -le "$rounds" ]; do
    for mode in $modes; do
      case $mode in
        default) env="" opts="" ;;
        one_thread) env="OMP_NUM_THREADS=1" opts="" ;;
        tuned) env="" opts="-ksp_type cg -pc_type gamg -ksp_rtol 1e-8" ;;
        direct) env="" opts="-lugal_iterative 0" ;;
      esac
      # shellcheck disable=SC2086
      env $env /usr/bin/time -f "whole_s=%e rss_kb=%M" "$ROOT/build/lugal" "$ROOT/bench/$script" "$size" $extra $opts 2>&1 |
        tr '\n' ' ' | sed "s/^/$load $mode /"
      echo
    done
    r=$((r + 1))
  done
  busy_stop
done
echo "/proc/loadavg $(cat /proc/loadavg)"

#!/bin/sh
# campaign.sh MESH_SECONDS OTHER_SECONDS — the fuzzing campaign behind docs/reliability.md on
# a two-core machine: the mesh target on one core for MESH_SECONDS, the untangler and then
# the expression engine on the other for OTHER_SECONDS each. Needs `make build-fuzz/fuzz_mesh
# build-fuzz/fuzz_untangle build-fuzz/fuzz_expr` (./configure --with-fuzz). Prints, per
# target, the executions, the corpus and whatever it found (build-fuzz/<target>-crash-*, ...).
M=${1:-3600}
O=${2:-1800}
cd "$(dirname "$0")/../.." || exit 1
run() { # target seconds
  mkdir -p "build-fuzz/corpus-$1" "tests/fuzz/seeds/$1" "tests/data/hostile/$1"
  dict=
  [ -f "tests/fuzz/$1.dict" ] && dict="-dict=tests/fuzz/$1.dict"
  t0=$(date +%s)
  # shellcheck disable=SC2086
  "./build-fuzz/fuzz_$1" -max_total_time="$2" -timeout=20 -rss_limit_mb=3000 -print_final_stats=1 $dict \
    -artifact_prefix="build-fuzz/$1-" "build-fuzz/corpus-$1" "tests/fuzz/seeds/$1" "tests/data/hostile/$1" \
    > "build-fuzz/campaign-$1.log" 2>&1
  runs=$(grep -h stat::number_of_executed_units "build-fuzz/campaign-$1.log" | awk '{print $2}')
  [ -n "$runs" ] || runs=$(grep -oE '^#[0-9]+' "build-fuzz/campaign-$1.log" | tail -n 1 | tr -d '#')
  echo "$1: $runs executions in $(( $(date +%s) - t0 )) s," \
       "corpus $(ls "build-fuzz/corpus-$1" | wc -l) inputs, findings: $(ls build-fuzz/"$1"-* 2>/dev/null | grep -v corpus | wc -l)"
}
run mesh "$M" &
{ run untangle "$O"; run expr "$O"; } &
wait

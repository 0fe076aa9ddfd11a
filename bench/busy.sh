# bench/busy.sh — sourced by the benchmark scripts (. "$ROOT/bench/busy.sh"): busy_start
# starts the one busy process (sh -c 'while :; do :; done') that "beside one busy process"
# in bench/RESULTS.md means, busy_stop stops it and waits for it. A script that ends or is
# interrupted stops it too (a forgotten busy loop slowed later measurements and made the MPI
# tests time out); bench_cleanup, which a script may redefine, runs then as well.
bench_cleanup() { :; }
busy_pid=
busy_start() {
  sh -c 'while :; do :; done' &
  busy_pid=$!
}
busy_stop() {
  if [ -n "$busy_pid" ]; then
    kill "$busy_pid" 2> /dev/null
    wait "$busy_pid" 2> /dev/null
    busy_pid=
  fi
}
trap 'busy_stop; bench_cleanup' EXIT
trap 'exit 130' INT TERM

#!/bin/sh
# A misbehaving stand-in for an external simulator, used by the pipelines tests (not demcal code).
#
# usage: faulty_simulator.sh FAULT STIFFNESS FRICTION_DEG OUTPUT
#
# With FRICTION_DEG below 35 it behaves: OUTPUT gets a curve (columns top_horizontal in m, force in
# N, 21 rows) and it exits 0. From 35 up it commits FAULT:
#   exit-code      prints to stderr and exits 3           empty       writes a 0-byte OUTPUT
#   no-output      exits 0 without writing OUTPUT          huge-output  writes OUTPUT without end
#   huge-stdout    writes to stdout without end            nan / inf   a NaN / an inf in force
#   malformed      OUTPUT is not a curve                  ragged      a row with a missing cell
#   no-force       OUTPUT has no force column             one-row     OUTPUT has one data row
#   crash          dies of SIGSEGV                         hang        sleeps, with a child and a
#                                                                      grandchild sleeping too
#   hang-setsid    a child that calls setsid, then hangs   hang-double-fork  a double-forked
#                                                                      grandchild, then hangs
#   leave-daemon   a double-forked setsid grandchild that outlives it; OUTPUT is fine, exit 0
#   mixed          by FRICTION_DEG: < 32 fine, < 36 nan, < 39 hang-double-fork, else exit-code
# Every process it starts appends its pid to ./pids (the run's working directory).
fault=$1 k=$2 phi=$3 output=$4
pids="$PWD/pids"
echo $$ >> "$pids"

good() {
  awk -v k="$k" -v phi="$phi" -v bad="$1" 'BEGIN {
    print "top_horizontal,force"
    cap = 10000 * sin(phi * 3.14159265358979 / 180) / cos(phi * 3.14159265358979 / 180)
    for (i = 0; i <= 20; i++) {
      d = 0.01 * i / 20; f = cap * (1 - exp(-k * d / cap))
      if (i == 7 && bad != "") printf "%.17g,%s\n", d, bad; else printf "%.17g,%.17g\n", d, f
    }
  }' > "$output"
}

if [ "$fault" = mixed ]; then
  fault=$(awk -v phi="$phi" 'BEGIN { if (phi < 32) print "none"; else if (phi < 36) print "nan";
                                      else if (phi < 39) print "hang-double-fork"; else print "exit-code" }')
elif awk -v phi="$phi" 'BEGIN { exit !(phi < 35) }'; then
  fault=none
fi

sleeper() {  # a process that sleeps "forever" and records its pid
  sh -c 'echo $$ >> "$1"; exec sleep 1000' sleeper "$pids"
}

case "$fault" in
  none) good "" ;;
  exit-code) echo "solver diverged at step 12" >&2; exit 3 ;;
  empty) : > "$output" ;;
  no-output) ;;
  huge-output) exec yes "0.001,1.0" > "$output" ;;
  huge-stdout) exec yes "step 1 residual 0.5" ;;
  nan) good nan ;;
  inf) good inf ;;
  malformed) printf 'this is not a curve\n\001\002\003 binary garbage\n' > "$output" ;;
  ragged) good ""; echo "0.02" >> "$output" ;;
  no-force) good ""; sed -i 's/^top_horizontal,force$/top_horizontal,shear/' "$output" ;;
  one-row) printf 'top_horizontal,force\n0,0\n' > "$output" ;;
  crash) kill -SEGV $$ ;;
  hang) sleeper & ( sleeper & wait ) & exec sleep 1000 ;;
  hang-setsid) setsid sh -c 'echo $$ >> "$1"; exec sleep 1000' x "$pids" & exec sleep 1000 ;;
  hang-double-fork) ( sleeper & ) ; exec sleep 1000 ;;
  leave-daemon) ( setsid sh -c 'echo $$ >> "$1"; exec sleep 1000' x "$pids" & ) ; good ""
                while [ "$(wc -l < "$pids")" -lt 2 ]; do sleep 0.01; done ;;
  *) echo "faulty_simulator.sh: unknown fault '$fault'" >&2; exit 64 ;;
esac

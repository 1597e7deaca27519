#!/usr/bin/env bash
# The measurements of the 2026-12-01 night session in one device call, from the
# repository root with the kit and a release binary in .gpu/ (../shared/gpu/README.md):
# the lane kernels of spreading and interpolation (the spread table, with the
# workgroup-table kernels they replaced as "tables"), FCM with them (every tolerance,
# with noise; the equal-error rows at 3e-3 and 5e-5; the 1e-2, 10^5 breakdown), every
# FCM kernel, and PSE with the far field in cell-list order. Output also in $OUT/bench.log.
source benches/common.sh
run $bin bench spread --cells 128 --reps 20
run $bin bench fcm --noise --reps 20
run $bin bench fcm --tolerances 3e-3,5e-5 --sizes 128:100000,256:1000000 --reps 20
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench fcm --tolerances 1e-2 --sizes 127:100000 --reps 20
run $bin bench pse --noise --reps 20
run $bin bench fcm --kernels es,peskin3,peskin4,peskin6 --reps 10 --plot "${OUT:-/tmp}/fcm_kernels.svg"
exit 0

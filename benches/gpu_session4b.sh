#!/usr/bin/env bash
# The last device call of the 2026-12-01 night session: the box kernel's shorter column
# sums (the spread table), FCM at 1e-3 again (10^5 sat at 0.996 ms, near the issue's
# 1.0 ms), and where PSE's time goes now (split 0.5, 10^5). Output also in $OUT/bench.log.
source benches/common.sh
run $bin bench spread --cells 128 --reps 20
run $bin bench fcm --tolerances 1e-3 --reps 20
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench pse --splits 0.5 --sizes 128:100000 --reps 20
exit 0

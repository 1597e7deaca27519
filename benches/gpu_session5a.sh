#!/usr/bin/env bash
# 2026-12-02, first device call: where FCM 1e-2 at 10^5 and PSE at 10^4 / 10^5 spend
# their time (per-dispatch GPU timestamps), and FCM without the particle sort.
source benches/common.sh
export MESOFLOW_BENCH_DISPATCHES=1
run $bin bench fcm --tolerances 1e-2 --sizes 127:100000 --reps 20
run $bin bench fcm --tolerances 1e-2,1e-3 --sizes 127:100000 --reps 20 --set sort_particles=false
run $bin bench pse --splits 0.6 --sizes 64:10000 --reps 20
run $bin bench pse --splits 0.5 --sizes 128:100000 --reps 20
unset MESOFLOW_BENCH_DISPATCHES
run $bin bench sort --help
exit 0

#!/usr/bin/env bash
# 2026-12-02, second device call: the near field with subgroup lanes (4, 8, 16 against
# one thread per particle), the counting-sort cell lists (bin_sort), the scatter without
# its clear, and the forward FFT's last pass running the inverse's first (FCM, PSE);
# the spread table with the counting sort (bin+box). Output also in $OUT/bench.log.
source benches/common.sh
export MESOFLOW_BENCH_DISPATCHES=1
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20
run $bin bench fcm --tolerances 1e-2,1e-3 --sizes 127:100000 --reps 20
unset MESOFLOW_BENCH_DISPATCHES
for lanes in off 4 16; do
  run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --set near_lanes=$lanes
done
run $bin bench pse --splits 0.4,0.8 --sizes 64:10000,128:100000 --reps 20 --noise
run $bin bench fcm --noise --reps 20
run $bin bench fcm --tolerances 7e-3,5e-3,3e-3,5e-5 --sizes 128:100000,256:1000000 --reps 20
run $bin bench spread --cells 128 --reps 20
run $bin bench fft --sizes 64,128,162,192,256,384 --reps 20 --filter
run $bin bench fft --sizes 128,162,192,256 --reps 20
exit 0

#!/usr/bin/env bash
# 2026-12-02, third device call: the fused FFT pass with the later components' loads
# issued first and at most 8 registers per component; bin_sort's one-workgroup scan
# with coalesced, all-at-once loads; PSE's far field cut at 6 cells at 1e-3 (the
# Lindbo-Tornberg width of 7, cut where the tolerance allows), against 7 (--set).
# Output also in $OUT/bench.log.
source benches/common.sh
export MESOFLOW_BENCH_DISPATCHES=1
run $bin bench pse --splits 0.5 --sizes 64:10000,128:100000 --reps 20
run $bin bench fcm --tolerances 1e-2 --sizes 127:100000 --reps 20
unset MESOFLOW_BENCH_DISPATCHES
run $bin bench fft --sizes 54,108,128,162,192,256,384 --reps 20 --filter
run $bin bench pse --noise --reps 20
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --set support=7
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --set near_lanes=16
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --set near_lanes=1
run $bin bench fcm --noise --reps 20
run $bin bench fcm --tolerances 7e-3,5e-3,3e-3,5e-5 --sizes 128:100000,256:1000000 --reps 20
exit 0

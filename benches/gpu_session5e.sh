#!/usr/bin/env bash
# 2026-12-02, fifth device call: spreading by cells (lane k took cell k + r seg of the
# ns^3 support) where the (x, y) columns leave lanes idle (supports 5, 6, 7 on 32
# lanes); measured slower or no faster, and removed (BENCHMARKS.md). Kept as the record
# of what was run.
source benches/common.sh
export MESOFLOW_BENCH_DISPATCHES=1
run $bin bench fcm --tolerances 1e-2,3e-3,1e-3 --sizes 128:100000 --reps 20
run $bin bench pse --splits 0.5 --sizes 128:100000 --reps 20
unset MESOFLOW_BENCH_DISPATCHES
run $bin bench fcm --reps 40
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 40 --noise
run $bin bench fcm --tolerances 3e-3,5e-5 --sizes 128:100000,256:1000000 --reps 20
exit 0

#!/usr/bin/env bash
# The measurements of BENCHMARKS.md's 2026-12-01 sections in one device call: spreading
# (per-particle and box kernels), FCM (Gaussian, with noise), PSE per split (with noise)
# and where PSE's time goes. Output also in $OUT/bench.log.
source benches/common.sh
run $bin bench spread --cells 128 --reps 20 --workgroups 256
run $bin bench fcm --noise --reps 20
run $bin bench pse --noise --reps 20
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench pse --splits 0.5 --sizes 128:100000 --noise --reps 10
exit 0

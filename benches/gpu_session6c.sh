#!/usr/bin/env bash
# 2026-12-02, session 6, third device call: kernels built without naga's loop bounds and
# index clamps (the new default, MESOFLOW_RUNTIME_CHECKS unset), and tiled spreading
# (tilegen.rs; `tiles` rows, `spread_tiles` in fcm.json and pse.json): the spread table,
# FCM and PSE with and without tiles, then every table the issues' targets rest on.
source benches/common.sh
run $bin bench spread --cells 128 --reps 10
for t in on off; do
  run $bin bench fcm --tolerances 1e-2,3e-3,1e-3 --sizes 128:100000 --reps 20 --set spread_tiles=$t
  run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --set spread_tiles=$t
done
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench pse --splits 0.5 --sizes 128:100000 --reps 20
run $bin bench fcm --noise --reps 20
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --noise
run $bin bench fft --reps 20
run $bin bench mpcd
exit 0

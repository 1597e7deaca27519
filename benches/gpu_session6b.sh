#!/usr/bin/env bash
# 2026-12-02, session 6, second device call: (1) the atomic-add rates again with almost
# no address arithmetic around them (benches/atomics.cu, CUDA, "light" rows; the first
# rows of session 6a were partly bound by their own integer work), global and
# workgroup (shared) memory; (2) what naga's runtime checks cost (MESOFLOW_RUNTIME_CHECKS:
# all = wgpu's default, noloop = loops not force-bounded, noloopdiv = also no division
# guards, none = no checks at all) on the kernels the targets rest on; (3) the FCM table
# with noise on this binary.
source benches/common.sh
nvcc -O3 -arch=sm_90 benches/atomics.cu -o /tmp/atomics 2>&1 | tee -a "$log"
run /tmp/atomics
for mode in all noloop noloopdiv none; do
  export MESOFLOW_RUNTIME_CHECKS=$mode
  echo "######## runtime checks: $mode" | tee -a "$log"
  run $bin bench spread --cells 128 --reps 10
  run $bin bench fcm --tolerances 1e-2,3e-3,1e-3 --sizes 128:100000 --reps 20
  run $bin bench fft --sizes 162,192 --reps 20
  run $bin bench pse --splits 0.5 --sizes 128:100000 --reps 20
done
unset MESOFLOW_RUNTIME_CHECKS
run $bin bench fcm --noise --reps 20
exit 0

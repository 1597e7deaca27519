#!/usr/bin/env bash
# The measurements waiting for a GPU (written 2026-12-01 evening, when none was lent):
# one device call, from the repository root, with the kit and a release binary in .gpu/
# (../shared/gpu/README.md). Each pair of rows compares a change with what it replaced,
# in the same call:
#   - MPCD cell sums: native 64-bit atomics on 32-byte cells without the energy block
#     (the default now) against int32 pairs (`--set atomics=int32`, the old atomics on the
#     new layout); streaming and binning fused (graphs/mpcd.json) against unfused
#     (graphs/fixtures/mpcd_unfused.json); per dispatch, unsorted and sorted every step
#     (sort_every=1); then sorted every 5, 10, 20 steps (rates from the mean step).
#   - The 16-byte fill (engine/fill4.wgsl) shows in every clear: FCM's grid clear at 384^3
#     (0.44 ms on the H100 with the 4-byte fill), MPCD's sums clear.
#   - FCM, spread and PSE tables again (the fill is in all of them).
# A torch copy in the same call gives the copy bandwidth. Output also in $OUT/bench.log.
#   bash benches/gpu_next.sh [mpcd] [fcm] [rest]     (default all three; each under 10 minutes)
source benches/common.sh
want=("$@")
[ ${#want[@]} -eq 0 ] && want=(mpcd fcm rest)
has() { [[ " ${want[*]} " == *" $1 "* ]]; }
run $bin info
if has mpcd; then
  export MESOFLOW_BENCH_DISPATCHES=1
  run $bin bench mpcd --reps 20
  run $bin bench mpcd --reps 20 --set atomics=int32
  run $bin bench mpcd --reps 20 --graph graphs/fixtures/mpcd_unfused.json
  run $bin bench mpcd --reps 20 --sizes 10000000,50000000 --set sort_every=1
  unset MESOFLOW_BENCH_DISPATCHES
  for k in 5 10 20; do run $bin bench mpcd --reps 40 --sizes 10000000,50000000 --set sort_every=$k; done
  run python3 benches/torch_reduce.py
fi
if has fcm; then
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench fcm --tolerances 1e-3 --reps 20
  run $bin bench fcm --noise --reps 20
fi
if has rest; then
  run $bin bench spread --cells 128 --reps 20 --workgroups 256
  run $bin bench pse --noise --reps 20
fi
exit 0

#!/usr/bin/env bash
# 2026-12-02, last device call: the same binary as gpu_session5c.sh, again (run-to-run
# spread of the rows the targets rest on), plus the FFT sizes of the strict 1e-2 row.
source benches/common.sh
run $bin bench fcm --reps 40
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 40 --noise
run $bin bench fcm --tolerances 3e-3 --sizes 128:100000 --reps 40
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench fcm --tolerances 3e-3 --sizes 128:100000 --reps 20
run $bin bench fft --sizes 162,168,175,180,192 --reps 20
exit 0

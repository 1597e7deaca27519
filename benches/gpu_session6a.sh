#!/usr/bin/env bash
# 2026-12-02, session 6, first device call: the atomic-add rates by access pattern
# (benches/atomics.cu, CUDA on the same GPU), then ncu's L2 request and sector counts for
# the same patterns, and the current spreading rows as the baseline.
source benches/common.sh
nvcc -O3 -arch=sm_90 benches/atomics.cu -o /tmp/atomics 2>&1 | tee -a "$log"
run /tmp/atomics
timeout 240 ncu --clock-control none --metrics lts__t_sectors_op_red.sum,lts__t_requests_srcunit_tex_op_red.sum,lts__t_sectors_op_atom.sum,lts__t_requests_srcunit_tex_op_atom.sum,gpu__time_duration.sum /tmp/atomics once 2>&1 | grep -E 'global_rows|lts__|gpu__time' | tee -a "$log"
run $bin bench spread --cells 128 --reps 10
exit 0

#!/usr/bin/env bash
# 2026-12-02, session 6, after the review: tiled spreading lists its particles with
# bin_sort's counting sort (one key kernel, then bin_sort's clear, rank, one-workgroup
# scan and place) instead of its own rank, scan and place: the spread table again.
source benches/common.sh
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench spread --cells 128 --reps 10 --cases 2
run $bin bench spread --cells 128 --reps 10
exit 0

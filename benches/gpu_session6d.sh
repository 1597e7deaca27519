#!/usr/bin/env bash
# 2026-12-02, session 6, last device call: the final binary (tiles chosen by support
# overlap, box kernel first for dense sorted input): the spread table again (run-to-run
# spread), FCM and PSE as the graphs now run them by default, every FCM kernel with the
# plot, and the FCM rows at the tolerances that reach UAMMD's quoted errors by the worst
# of 16 positions.
source benches/common.sh
run $bin bench spread --cells 128 --reps 10
run $bin bench pse --splits 0.5,0.6 --sizes 64:10000,128:100000 --reps 20 --noise
run $bin bench fcm --noise --reps 20
run $bin bench fcm --tolerances 3e-3,5e-5 --sizes 128:100000,256:1000000 --reps 20
run $bin bench fcm --kernels es,peskin3,peskin4,peskin6 --reps 10 --plot $OUT/fcm_kernels.svg
exit 0

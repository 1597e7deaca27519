#!/usr/bin/env bash
# One device call: spreading kernels (per-particle and box kernels), FCM with sorting,
# PSE with sorting. Output also in $OUT/bench.log.
set -uo pipefail
source .gpu/gpu-env.sh
bin=.gpu/mesoflow
log=${OUT:-/tmp}/bench.log
: > "$log"
run() { echo "== $*" | tee -a "$log"; "$@" 2>&1 | tee -a "$log"; }
echo "date: $(date -u +%Y-%m-%dT%H:%MZ)" | tee -a "$log"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee -a "$log"
run $bin bench spread --cells 128 --reps 20 --workgroups 256
run $bin bench fcm --reps 20 --tolerances 1e-3 --set sort_particles=true --error-samples 4
MESOFLOW_BENCH_DISPATCHES=1 run $bin bench pse --splits 0.5 --sizes 128:100000 --set sort_particles=true --reps 10
exit 0

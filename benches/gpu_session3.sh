#!/usr/bin/env bash
# One device call: spreading kernels (per-particle and box kernels), FCM with sorting,
# PSE with and without sorting. Output also in $OUT/bench.log.
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
run $bin bench pse --reps 20 --noise --splits 0.4,0.5,0.6 --set sort_particles=true
exit 0

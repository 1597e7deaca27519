# Sourced by benches/gpu.sh and benches/gpu_variants.sh (from the repository root, with
# the kit and a release binary in .gpu/): the GPU environment, `bin`, a log in
# $OUT/bench.log, `run` (echo a command, run it, keep its output in the log) and a header
# with the date, the GPU and its driver.
set -uo pipefail
source .gpu/gpu-env.sh
export PYTHONUNBUFFERED=1
bin=.gpu/mesoflow
log=${OUT:-/tmp}/bench.log
: > "$log"
run() { echo "== $*" | tee -a "$log"; "$@" 2>&1 | tee -a "$log"; }
echo "date: $(date -u +%Y-%m-%dT%H:%MZ)" | tee -a "$log"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee -a "$log"

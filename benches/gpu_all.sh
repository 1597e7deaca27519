#!/usr/bin/env bash
# Every GPU measurement in one call on the GPU machine (device tool), from the repository
# root, with the kit and a release binary in .gpu/ (see ../shared/gpu/README.md):
#   bash benches/gpu_all.sh [names...]     names: overhead reduce sort scan spread fft fcm pse torch (default all)
# Prints each table; copies the full log to $OUT/bench.log when OUT is set.
set -uo pipefail
source .gpu/gpu-env.sh
export PYTHONUNBUFFERED=1
bin=.gpu/mesoflow
want=("$@")
[ ${#want[@]} -eq 0 ] && want=(overhead reduce sort scan spread fft fcm pse torch)
log=${OUT:-/tmp}/bench.log
: > "$log"
has() { [[ " ${want[*]} " == *" $1 "* ]]; }
run() { echo "== $*" | tee -a "$log"; "$@" 2>&1 | tee -a "$log"; }
echo "date: $(date -u +%Y-%m-%dT%H:%MZ)" | tee -a "$log"
nvidia-smi --query-gpu=name,driver_version,clocks.max.sm,clocks.max.mem --format=csv,noheader | tee -a "$log"
has overhead && run $bin bench overhead --nodes 1000 --reps 50
has reduce && run $bin bench reduce --n 100000000 --reps 20
has sort && $bin bench sort --help >/dev/null 2>&1 && run $bin bench sort --n 10000000 --reps 20 --variant all
has scan && $bin bench scan --help >/dev/null 2>&1 && run $bin bench scan --n 100000000 --reps 20
has spread && run $bin bench spread --cells 128 --reps 20
has fft && $bin bench fft --help >/dev/null 2>&1 && run $bin bench fft --comps 3 --reps 20
has fcm && run $bin bench fcm --noise --reps 20 --plot ${OUT:-/tmp}/fcm_gaussian.svg
has fcm && run $bin bench fcm --kernels es,peskin3,peskin4,peskin6 --reps 10 --plot ${OUT:-/tmp}/fcm_kernels.svg
has pse && run $bin bench pse --noise --reps 20
has pse-profile && MESOFLOW_BENCH_DISPATCHES=1 run $bin bench pse --splits 0.4 --sizes 128:100000 --noise --reps 10
if has torch; then
  for s in benches/torch_*.py; do [ -f "$s" ] && run python3 "$s"; done
fi
exit 0

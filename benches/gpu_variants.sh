#!/usr/bin/env bash
# Kernel variants timed side by side in one device call: each folder under
# benches/variants/ holds shader files that replace the embedded ones of the same path
# (MESOFLOW_SHADER_DIR), so a variant needs no rebuild. From the repository root with the
# kit and a release binary in .gpu/ (../shared/gpu/README.md):
#   bash benches/gpu_variants.sh CASES VARIANT...    (CASES: rows of `bench spread`, e.g. 0,2,6;
#                                                    VARIANT "base" is the embedded shaders)
# The variants under benches/variants/interp_* replace files of the workgroup-table
# interpolation kernel: since the lane kernels (generated, nodes/spread/interpgen.rs) they
# show in the rows labelled "tables" only.
set -uo pipefail
source .gpu/gpu-env.sh
bin=.gpu/mesoflow
log=${OUT:-/tmp}/bench.log
cases=$1; shift
echo "date: $(date -u +%Y-%m-%dT%H:%MZ)" | tee -a "$log"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee -a "$log"
for v in "$@"; do
  echo "== variant $v" | tee -a "$log"
  if [ "$v" = base ]; then
    $bin bench spread --cells 128 --reps 20 --cases "$cases" 2>&1 | tee -a "$log"
  else
    MESOFLOW_SHADER_DIR=benches/variants/$v $bin bench spread --cells 128 --reps 20 --cases "$cases" 2>&1 | tee -a "$log"
  fi
done
exit 0

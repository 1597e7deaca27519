#!/usr/bin/env bash
# Kernel variants timed side by side in one device call: benches/variants.py writes each
# variant as a folder of shader files that replace the embedded ones of the same path
# (MESOFLOW_SHADER_DIR), so a variant needs no rebuild. From the repository root with the
# kit and a release binary in .gpu/ (../shared/gpu/README.md):
#   bash benches/gpu_variants.sh CASES VARIANT...    (CASES: rows of `bench spread`, e.g. 0,2,6;
#                                                    VARIANT "base" is the embedded shaders)
# The interp_* variants replace files of the workgroup-table interpolation kernel: since
# the lane kernels (generated, nodes/spread/interpgen.rs) they show in the rows labelled
# "tables" only. VARIANT_BENCH=dpstokes times DP Stokes' bottom-wall rows instead (CASES
# then its sizes, e.g. 100000,1000000; VARIANT_SLAB its --slab, e.g. lanes for the lanes_*
# variants), with its dispatches.
source benches/common.sh
cases=$1; shift
dir=${OUT:-/tmp}/variants
python3 benches/variants.py "$dir" > /dev/null
bench() {
  if [ "${VARIANT_BENCH:-spread}" = dpstokes ]; then
    MESOFLOW_BENCH_DISPATCHES=1 $bin bench dpstokes --walls bottom --sizes "$cases" --reps 10 \
      ${VARIANT_SLAB:+--slab $VARIANT_SLAB}
  else
    $bin bench spread --cells 128 --reps 20 --cases "$cases"
  fi
}
for v in "$@"; do
  echo "== variant $v" | tee -a "$log"
  if [ "$v" = base ]; then
    bench 2>&1 | tee -a "$log"
  else
    MESOFLOW_SHADER_DIR=$dir/$v bench 2>&1 | tee -a "$log"
  fi
done
exit 0

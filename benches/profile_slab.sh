#!/usr/bin/env bash
# On the GPU machine: builds benches/slab_solve_three_lines.cu (the three-lines slab_solve
# ported to CUDA) for the bottom wall's 10^5 grid (175 x 175, 30 points) and 10^6 grid
# (560 x 560, 31 points), times each against a copy of the same bytes, and profiles each
# under Nsight Compute (occupancy, launch, scheduler and warp-state sections). Writes
# $OUT/profile_slab.log (or /tmp) and prints the lines that matter.
set -uo pipefail
cd "$(dirname "$0")/.."
log=${OUT:-/tmp}/profile_slab.log
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | tee -a "$log"
# Nsight Compute's warp stall reasons, each per issued instruction.
stalls=long_scoreboard,short_scoreboard,wait,math_pipe_throttle,barrier,lg_throttle,not_selected,selected,mio_throttle,no_instruction,dispatch_stall,imc_miss,drain,branch_resolving,membar,sleeping,tex_throttle
metrics=$(tr , '\n' <<< "$stalls" | sed 's/.*/smsp__average_warps_issue_stalled_&_per_issue_active.ratio/' | paste -sd,)
for case in 30:175 31:560; do
  n=${case%:*} side=${case#*:}
  bin=/tmp/slab$n
  nvcc -O3 -arch=sm_90 -Xptxas -v -DPOINTS=$n benches/slab_solve_three_lines.cu -o $bin 2>&1 \
    | grep -E "registers|spill|error" | tee -a "$log"
  $bin $side $side 2>&1 | tee -a "$log"
  ncu --section LaunchStats --section Occupancy --section SchedulerStats --section WarpStateStats \
    -k slab_solve -c 1 $bin $side $side >> "$log" 2>&1
  ncu --metrics "$metrics,smsp__inst_executed.sum,sm__cycles_elapsed.avg,dram__throughput.avg.pct_of_peak_sustained_elapsed,smsp__warps_active.avg.per_cycle_active" \
    -k slab_solve -c 1 $bin $side $side > /tmp/metrics$n.log 2>&1
  cat /tmp/metrics$n.log >> "$log"
  grep -E "Registers Per|Achieved Occupancy|Theoretical Occupancy|Issued Warp Per|No Eligible|Active Warps Per Scheduler|Eligible Warps Per|Warp Cycles Per Issued" "$log" | tail -n 9
  grep -E "smsp__|sm__|dram__|ERR|rror" /tmp/metrics$n.log
done

#!/usr/bin/env bash
# The GPU benchmarks as named suites: each runs the `mesoflow bench` commands behind the
# tables of BENCHMARKS.md and the peers measured in the same call (PyTorch's cuFFT and
# CUB through benches/torch_*.py, CUDA through benches/atomics.cu). On the GPU machine,
# from the repository root, with the kit and a release binary in .gpu/
# (../shared/gpu/README.md):
#
#   bash benches/gpu.sh SUITE...
#
#   fcm         FCM against UAMMD (Gaussian, with noise; plot), the tolerances that reach
#               UAMMD's quoted errors, every kernel (plot), where 10^5 spends its time,
#               Brownian dynamics (the colloids example) at 10^4 and 10^5
#   pse         PSE per split with noise, where split 0.5 at 10^5 spends its time
#   poisson     Poisson per tolerance and size (fastest split, errors, fcm.json beside it),
#               where 10^5 at 1e-3 spends its time
#   dpstokes    doubly periodic Stokes per wall mode at 10^4, 10^5, 10^6, ES windows then
#               Gaussian (errors, fcm.json on a grid of the same points beside it), where
#               bottom spends its time with the fused, staged or chained slab solve and the
#               workgroup or lane kernels
#               and 10^4, 10^6 (the boundary-value solves' GB/s), torch's copy bandwidth
#               and its copy of the bytes each slab solve moves (benches/torch_copy.py)
#   stream      bd_fcm.json at 10^6 for 1000 steps, with and without a frame every 100
#               steps streamed to GSD and NPY (`run --every`): the run's wall time
#   scene       scenes/colloids.json (the main job) against the hand-written bd_fcm.json on
#               the same particles, 10^4 / 10^5 / 10^6 for 500 steps, two rounds: the
#               run's wall time; the demo's diffusion check from a streamed trajectory
#               (SCENE_SIZES="N:L ..." times those sizes only, without the demo)
#   nbody       the direct pair mobilities, open and above a wall, translation and grand:
#               pair interactions per second and GFLOP/s
#   python      a Python loop of libMobility-style Mdot calls against the GPU time of one
#               product (benches/python_mdot.py; the package unpacked in .gpu/py), and
#               `bench fcm` at the same size beside it
#   mpcd        MPCD particle-steps per second, per dispatch, torch's copy bandwidth
#   spheres     the friction of a fixed sphere in flow against S2 Table 5.4 (R = 1, 2, 4,
#               L = 16R, M = 5, MPCD-BC A = 0.01, dt 0.02, Monte-Carlo thermostat;
#               SPHERES_ROWS="1 2" for fewer)
#   spheres_acf the same sphere's friction from the fluid momentum's autocorrelation (R = 1),
#               the instantaneous friction (R = 2), a moving sphere's velocity
#               autocorrelation (R = 2) (benches/sphere_friction.py)
#   spheres_rates  MPCD particle-steps per second with 1, 8, 64 spheres of R = 4 (fixed,
#               moving) in 128^3 cells, the biased rule with the Monte-Carlo thermostat in
#               3D and 2D, against sphere-free SRD at the same N
#   poiseuille  MPCD-BC Poiseuille flow between plates against S2 4.4 (40 x 20 x 80, M = 5,
#               A = 0.01, Monte-Carlo thermostat; (a) dt 0.01, F 1.5e-4; (b) dt 0.005,
#               F 2.5e-4; 200000 steps of warm-up, 300000 averaged): the mean velocity
#               against 0.0436 and 0.0406 (benches/poiseuille.py)
#   disks       Brownian disks with a Delaunay mesh (bd_delaunay.json): c0 and c4 short at
#               2^20 with the step's loops chained and with --no-chain; the step split into
#               forces, flips, overlap correction for c0 to c4, long range, short range
#               (cell list) and the Verlet variant, 2^10 to 2^20 (DISKS_SIZES,
#               DISKS_CONFIGS to change), the long-range pair interactions per second;
#               the long-range forces against an f64 sum (benches/disk_forces_check.py);
#               c0 and c4 short at 2^14 and 2^20 with the disks numbered in lattice
#               order; c0's launches with fixed loops (benches/bd_delaunay_fixed.json)
#   spread      spreading and interpolation (UAMMD's setups), the tile kernel per dispatch
#   atomics     global and workgroup atomic-add rates by access pattern (CUDA), ncu's L2
#               request counts
#   fft         rfft + irfft against cuFFT (torch), convolutions (a folded filter)
#   primitives  reduce, sort (every variant), scan against CUB (torch)
#   overhead    the executor against raw wgpu
#   kernels     what the driver makes of DP Stokes' kernels (`mesoflow kernel-stats`:
#               registers, code size, workgroup memory as the driver reports them): the
#               slab, spreading and interpolation kernels at 10^5 (bottom wall and none),
#               internal representations in $OUT/kernel_ir.tgz where the driver gives
#               them (NVIDIA's 580 driver gives none); then the lanes kernel timed at 10^5
#               and 10^6 with each of its steps taken out in turn (benches/variants.py)
#   determinism FCM (1e-3) and PSE (split 0.5) at 10^4 and 10^5, default and
#               --deterministic; two identical runs of each at 10^5 compared word by word
#   all         every suite above, in this order
#   compare     the FCM, PSE, spread, FFT and MPCD rows timed with $BEFORE (another
#               release binary, e.g. .gpu/mesoflow-before) and with .gpu/mesoflow,
#               alternating ROUNDS times (2): that a change left the speed as it was
#               (not in `all`); COMPARE_SET=dpstokes times the DP Stokes bottom-wall
#               rows instead, COMPARE_SET=disks the disks' short-range c0 and c4 rows
#
# Each suite is sized for one device call (ten minutes at most). The log, headed once by
# the date, the GPU, its driver and mesoflow's adapter line, goes to $OUT/bench.log (/tmp
# without OUT); plots to $OUT.
set -uo pipefail
suites=(fcm pse poisson dpstokes nbody python mpcd spheres spheres_acf spheres_rates poiseuille disks spread atomics fft primitives overhead determinism stream scene kernels)
usage() { sed -n '2,/^set -uo/{/^#/p}' "$0" | sed 's/^# \{0,1\}//'; }
want=()
for s in "$@"; do
  case " ${suites[*]} all compare " in
    *" $s "*) ;;
    *) echo "gpu.sh: no suite \`$s\`" >&2; usage >&2; exit 2 ;;
  esac
  if [ "$s" = all ]; then want+=("${suites[@]}"); else want+=("$s"); fi
done
if [ ${#want[@]} -eq 0 ]; then usage >&2; exit 2; fi
source benches/common.sh
out=${OUT:-/tmp}
run $bin info

suite_fcm() {
  run $bin bench fcm --noise --reps 20 --plot "$out/fcm_gaussian.svg"
  run $bin bench fcm --tolerances 3e-3,5e-5 --sizes 128:100000,256:1000000 --reps 20
  run $bin bench fcm --kernels es,peskin3,peskin4,peskin6 --reps 10 --plot "$out/fcm_kernels.svg"
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench fcm --tolerances 1e-2 --sizes 127:100000 --reps 20
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench fcm --tolerances 1e-3 --sizes 129:100000 --reps 20
  for size in 10000:64 100000:128; do
    run $bin run graphs/examples/colloids.json --set n=${size%:*} --set side=${size#*:} \
      --steps 500 --seed 1 --output diffusion --output theory
  done
}

suite_dpstokes() {
  run $bin bench dpstokes --reps 10
  run $bin bench dpstokes --kernel gaussian --reps 10
  for k in workgroup lanes; do
    MESOFLOW_BENCH_DISPATCHES=1 run $bin bench dpstokes --walls bottom --sizes 10000,100000,1000000 \
      --reps 10 --slab fused,staged,chain --spread-kernel $k
  done
  run python3 benches/torch_reduce.py
  # torch's copy of the bytes each default slab_solve moves (BENCHMARKS.md: bottom at 10^4,
  # 10^5, 10^6; the slit and no walls at 10^6).
  run python3 benches/torch_copy.py 3.5 31.8 335.5 327.3 378.3
}

suite_nbody() {
  run $bin bench nbody --reps 10
}

suite_python() {
  PYTHONPATH=.gpu/py run python3 benches/python_mdot.py --calls 1000 --rounds 3
  run $bin bench fcm --tolerances 1e-3 --sizes 128:100000 --reps 20
}

suite_poisson() {
  run $bin bench poisson --reps 20
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench poisson --tolerances 1e-3 --sizes 128:100000 --reps 20
}

suite_pse() {
  run $bin bench pse --noise --reps 20
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench pse --splits 0.5 --sizes 128:100000 --reps 20
}

suite_mpcd() {
  run $bin bench mpcd --reps 20
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench mpcd --reps 20
  run python3 benches/torch_reduce.py
}

suite_spread() {
  run $bin bench spread --cells 128 --reps 10
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench spread --cells 128 --reps 10 --cases 2
}

suite_atomics() {
  local exe=$out/atomics
  nvcc -O3 -arch=sm_90 benches/atomics.cu -o "$exe" 2>&1 | tee -a "$log"
  run "$exe"
  if command -v ncu >/dev/null; then
    echo "== ncu L2 requests and sectors of the same patterns" | tee -a "$log"
    timeout 240 ncu --clock-control none --metrics lts__t_sectors_op_red.sum,lts__t_requests_srcunit_tex_op_red.sum,lts__t_sectors_op_atom.sum,lts__t_requests_srcunit_tex_op_atom.sum,gpu__time_duration.sum "$exe" once 2>&1 \
      | grep -E 'global_rows|lts__|gpu__time' | tee -a "$log"
  fi
  rm -f "$exe"
}

suite_fft() {
  local sizes=64,96,128,162,168,175,180,189,192,216,256,375,384
  run $bin bench fft --sizes $sizes --comps 3 --reps 20
  run python3 benches/torch_fft.py --sizes $sizes --comps 3 --reps 20
  run $bin bench fft --sizes 54,108,128,162,192,256,384 --comps 3 --reps 20 --filter
}

suite_primitives() {
  run $bin bench reduce --n 100000000 --reps 20
  run python3 benches/torch_reduce.py
  run $bin bench sort --n 10000000 --reps 20 --variant all
  run $bin bench scan --n 100000000 --reps 20
  run python3 benches/torch_primitives.py --sort-n 10000000 --scan-n 100000000 --reps 20
}

# Rows that every binary since the session-6 one understands (per-launch medians);
# COMPARE_SET=dpstokes: the DP Stokes bottom-wall rows instead (binaries since 2026-12-05);
# COMPARE_SET=disks: the disks' short-range rows (binaries since 2026-12-06).
compare_rows() {
  local b=$1
  if [ "${COMPARE_SET:-}" = dpstokes ]; then
    run $b bench dpstokes --walls bottom --sizes 10000,100000,1000000 --reps 10
    return
  fi
  if [ "${COMPARE_SET:-}" = disks ]; then
    run $b bench disks --configs c0,c4 --ranges short --sizes 16384,1048576 --reps 5
    return
  fi
  run $b bench fcm --tolerances 1e-2,1e-3,1e-4 --sizes 128:100000 --reps 20
  run $b bench pse --splits 0.5 --sizes 128:100000 --reps 20
  run $b bench spread --cells 128 --reps 10
  run $b bench fft --sizes 128,162,192 --comps 3 --reps 20
  run $b bench mpcd --reps 20
}

suite_compare() {
  if [ ! -x "${BEFORE:-}" ]; then
    echo "gpu.sh compare: set BEFORE to the other binary" | tee -a "$log"
    return
  fi
  for round in $(seq 1 "${ROUNDS:-2}"); do
    echo "######## compare round $round: before ($BEFORE)" | tee -a "$log"
    compare_rows "$BEFORE"
    echo "######## compare round $round: after ($bin)" | tee -a "$log"
    compare_rows "$bin"
  done
}

suite_determinism() {
  for mode in "" --deterministic; do
    run $bin bench fcm --tolerances 1e-3 --sizes 65:10000,129:100000 --reps 20 \
      --error-samples 4 $mode
    run $bin bench pse --splits 0.5 --sizes 64:10000,128:100000 --reps 20 $mode
  done
  local dir=$out/repro
  mkdir -p "$dir"
  for case in fcm:129 pse:128; do
    local graph=${case%:*} side=${case#*:}
    python3 benches/reproducible.py inputs "$dir" 100000 "$side"
    for mode in default deterministic; do
      local flag=""
      [ "$mode" = deterministic ] && flag=--deterministic
      for k in 1 2; do
        $bin run graphs/$graph.json --set "box=[$side,$side,$side]" $flag \
          --input positions="$dir/positions.npy" --input forces="$dir/forces.npy" \
          --output velocities="$dir/$graph-$mode-$k.npy" >/dev/null 2>&1 \
          || echo "run $graph $mode $k failed" | tee -a "$log"
      done
      run python3 benches/reproducible.py compare "$dir/$graph-$mode-1.npy" \
        "$dir/$graph-$mode-2.npy" "$graph.json N=10^5 L=$side $mode"
    done
  done
  rm -rf "$dir"
}

# Streaming frames (`run --every`): bd_fcm.json, 10^6 spheres in a box of 256 (a = 1,
# tolerance 1e-3), 1000 steps, without frames and with a frame every 100 steps to GSD and
# to NPY (to the machine's /tmp); twice each, alternating; the run's wall time.
suite_stream() {
  local dir=/tmp/mesoflow-stream
  mkdir -p "$dir"
  python3 -c "import numpy as np; np.save('$dir/x.npy', np.random.default_rng(1).uniform(-128, 128, (1000000, 3)).astype(np.float32))"
  local common=(graphs/bd_fcm.json --set "box=[256,256,256]" --set temperature=1 --input positions="$dir/x.npy" --steps 1000)
  for round in 1 2; do
    for mode in none gsd npy; do
      local extra=(--output positions="$dir/end.npy")
      [ "$mode" = gsd ] && extra=(--every 100 --output positions="$dir/t.gsd")
      [ "$mode" = npy ] && extra=(--every 100 --output positions="$dir/t.npy")
      echo "== stream $mode round $round" | tee -a "$log"
      $bin run "${common[@]}" "${extra[@]}" 2>&1 | grep -E "steps in|frames|->" | tee -a "$log"
    done
  done
  ls -la "$dir" | tee -a "$log"
  rm -rf "$dir"
}

suite_scene() {
  local dir=/tmp/mesoflow-scene
  mkdir -p "$dir"
  for size in ${SCENE_SIZES:-10000:64 100000:128 1000000:256}; do
    local n=${size%:*} side=${size#*:}
    python3 - "$dir" "$n" "$side" <<'PY'
import json, sys
import numpy as np
d, n, side = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
np.save(f"{d}/x.npy", np.random.default_rng(1).uniform(-side / 2, side / 2, (n, 3)).astype(np.float32))
scene = json.load(open("scenes/colloids.json"))
scene["box"] = [side] * 3
scene["particles"] = [{"species": "colloid", "positions": "x.npy"}]
scene.pop("output")
json.dump(scene, open(f"{d}/scene.json", "w"))
PY
    for round in 1 2; do
      echo "== scene n=$n side=$side round $round" | tee -a "$log"
      $bin run "$dir/scene.json" --steps 500 --output positions="$dir/a.npy" 2>&1 | grep -E "steps in" | tee -a "$log"
      echo "== bd_fcm.json n=$n side=$side round $round" | tee -a "$log"
      $bin run graphs/bd_fcm.json --set "box=[$side,$side,$side]" --set dt=0.05 --input positions="$dir/x.npy" \
        --steps 500 --seed 1 --output positions="$dir/b.npy" 2>&1 | grep -E "steps in" | tee -a "$log"
    done
  done
  if [ -z "${SCENE_SIZES:-}" ]; then
    echo "== the demo: scenes/colloids.json, every step streamed, diffusion against theory" | tee -a "$log"
    $bin run scenes/colloids.json --output positions="$dir/t.npy" --every 1 2>&1 | grep -E "steps in|->" | tee -a "$log"
    python3 scripts/diffusion.py "$dir/t.npy" 0.05 64 2>&1 | tee -a "$log"
  fi
  rm -rf "$dir"
}

# One fixed sphere of radius R at the origin of a (16R)^3 box pushed through by a body
# force on the solvent: xi = F_sphere / ((1 - phi) u) (S2 §5.6.3). Warm-up and averaging
# in relaxation times N m / xi of the mean flow (2.3 and 4.5 of them).
suite_spheres() {
  local dir=/tmp/mesoflow-spheres
  mkdir -p "$dir"
  for r in ${SPHERES_ROWS:-1 2 4}; do
    # R: force (mean flow about 0.15), warm-up and averaged steps (2.3 and 4.5 relaxation times)
    local force warmup steps
    case $r in
      1) force=6e-4 warmup=30000 steps=60000 ;;
      2) force=1.8e-4 warmup=95000 steps=185000 ;;
      4) force=5.2e-5 warmup=340000 steps=650000 ;;
    esac
    python3 -c "import numpy as np; np.save('$dir/p.npy', np.zeros((1, 3))); np.save('$dir/r.npy', np.full((1, 1), $r))"
    local l=$((16 * r))
    run $bin run graphs/mpcd_spheres.json --set "box=[$l,$l,$l]" --set density=5 --set dt=0.02 \
      --set rule=biased --set acceptance=0.01 --set thermostat=monte_carlo --set sphere_radius=$r \
      --set force=$force --set warmup=$warmup --steps $((warmup + steps)) --seed 7 \
      --input sphere_positions="$dir/p.npy" --input sphere_radii="$dir/r.npy" \
      --output sphere_forces --output momentum --output temperature
    python3 -c "import math; print(f'R = $r: N = {5 * $l**3}, phi = {4 / 3 * math.pi * $r**3 / $l**3:.6f}: xi = F_sphere / ((1 - phi) momentum_x / N)')" | tee -a "$log"
  done
  rm -rf "$dir"
}

# S2 §5.6.2's other routes to the friction: the fluid momentum's autocorrelation around a
# fixed sphere (R = 1; 2e6 steps, about 150 relaxation times), the instantaneous friction
# from every step's impulse (R = 2), and a moving, neutrally buoyant sphere's velocity
# autocorrelation (R = 2).
suite_spheres_acf() {
  local dir=/tmp/mesoflow-spheres
  mkdir -p "$dir"
  local common=(--set density=5 --set dt=0.02 --set rule=biased --set acceptance=0.01
    --set thermostat=monte_carlo --seed 11)
  python3 -c "import numpy as np; np.save('$dir/p.npy', np.zeros((1, 3))); [np.save(f'$dir/r{r}.npy', np.full((1, 1), r)) for r in (1, 2)]; np.save('$dir/m2.npy', np.full((1, 1), 5 * 4 / 3 * np.pi * 8))"
  run $bin run graphs/mpcd_spheres.json "${common[@]}" --set "box=[16,16,16]" --set sphere_radius=1 \
    --steps 2000000 --every 50 --input sphere_positions="$dir/p.npy" --input sphere_radii="$dir/r1.npy" \
    --output sphere_impulse="$dir/acf.npy"
  run python3 benches/sphere_friction.py acf "$dir/acf.npy" --every 50 --dt 0.02 --n 20480 --skip 200
  run $bin run graphs/mpcd_spheres.json "${common[@]}" --set "box=[32,32,32]" --set sphere_radius=2 \
    --steps 20000 --every 1 --input sphere_positions="$dir/p.npy" --input sphere_radii="$dir/r2.npy" \
    --output sphere_impulse="$dir/inst.npy"
  run python3 benches/sphere_friction.py instant "$dir/inst.npy" --dt 0.02 --skip 1000
  run $bin run graphs/mpcd_spheres.json "${common[@]}" --set "box=[32,32,32]" --set sphere_radius=2 \
    --set spheres=moving --steps 400000 --every 5 --input sphere_positions="$dir/p.npy" \
    --input sphere_radii="$dir/r2.npy" --input sphere_masses="$dir/m2.npy" \
    --output sphere_velocities="$dir/v.npy"
  run python3 benches/sphere_friction.py vacf "$dir/v.npy" --every 5 --dt 0.02 --skip 2000
  rm -rf "$dir"
}

suite_spheres_rates() {
  local n=20971520 # 128^3 cells at 10 particles a cell
  run $bin bench mpcd --sizes $n --reps 20
  for s in 1 8 64; do
    run $bin bench mpcd --sizes $n --reps 20 --spheres $s --sphere-radius 4
    run $bin bench mpcd --sizes $n --reps 20 --spheres $s --sphere-radius 4 --set spheres=moving
  done
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench mpcd --sizes $n --reps 20 --spheres 8 --sphere-radius 4
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench mpcd --sizes $n --reps 20 --spheres 64 --sphere-radius 4 --set sort_every=0
  # SPHERES_ONLY=1: the sphere rows and their reference only.
  if [ -z "${SPHERES_ONLY:-}" ]; then
    run $bin bench mpcd --sizes $n --reps 20 --set rule=biased --set thermostat=monte_carlo
    run $bin bench mpcd --sizes $n --reps 20 --dims 2
    run $bin bench mpcd --sizes $n --reps 20 --dims 2 --set rule=biased --set thermostat=monte_carlo
  fi
  run python3 benches/torch_reduce.py
}

suite_poiseuille() {
  local dir=$out/poiseuille run_set
  mkdir -p "$dir"
  for run_set in "0.01 1.5e-4 0.0436" "0.005 2.5e-4 0.0406"; do
    set -- $run_set
    run $bin run graphs/mpcd.json --set "box=[40,20,80]" --set walls=plates --set density=5 \
      --set dt=$1 --set rule=biased --set acceptance=0.01 --set thermostat=monte_carlo \
      --set force=$2 --set profile_bins=80 --set warmup=200000 --steps 500000 \
      --output momentum="$dir/momentum.npy" --output velocity_profile="$dir/profile.npy" \
      --output temperature="$dir/temperature.npy"
    run python3 benches/poiseuille.py "$dir" $3 $2 320000
  done
  rm -rf "$dir"
}

suite_disks() {
  # What chaining a step's loops in one submission saves (the same binary, --no-chain:
  # a host round trip per loop).
  run $bin bench disks --configs c0,c4 --ranges short --sizes 1048576 --reps 9
  run $bin bench disks --configs c0,c4 --ranges short --sizes 1048576 --reps 9 --no-chain
  run python3 benches/disk_forces_check.py $bin 65536
  run $bin bench disks --configs ${DISKS_CONFIGS:-c0,c1,c2,c3,c4} --ranges long,short,verlet \
    --sizes ${DISKS_SIZES:-1024,16384,65536,262144,1048576} --reps 5
  # The same start numbered in lattice order (memory locality of the mesh's kernels).
  run $bin bench disks --configs c0,c4 --ranges short --sizes 16384,1048576 --reps 9 --order lattice
  # Every launch of a step on the GPU clock: the loops run a fixed number of times.
  MESOFLOW_BENCH_DISPATCHES=1 run $bin bench disks --graph benches/bd_delaunay_fixed.json \
    --configs c0 --ranges short --sizes 1048576 --reps 5 --order lattice
}

suite_kernels() {
  # The variants here, not through gpu_variants.sh, whose common.sh would start the log again.
  local v=/tmp/variants
  rm -rf $v /tmp/kernel_dump /tmp/kernel_ir
  python3 benches/variants.py $v > /dev/null
  mkdir -p $v/base
  # One rep each: the kernels are built (and dumped) whatever their timing.
  MESOFLOW_KERNEL_DUMP=/tmp/kernel_dump $bin bench dpstokes --walls bottom,none \
    --sizes 100000 --reps 1 --slab lanes,fused > /dev/null 2>&1
  run $bin kernel-stats --ir /tmp/kernel_ir $(grep -l -E \
    "^// (slab solve|spread_chebyshev|interpolate_chebyshev)" /tmp/kernel_dump/*.wgsl)
  [ -d /tmp/kernel_ir ] && tar czf "$out/kernel_ir.tgz" -C /tmp kernel_ir
  for c in base lanes_skeleton lanes_nosolve lanes_notransform lanes_nodiff lanes_nowalls; do
    echo "== variant $c" | tee -a "$log"
    MESOFLOW_SHADER_DIR=$v/$c MESOFLOW_BENCH_DISPATCHES=1 run $bin bench dpstokes \
      --walls bottom --sizes 100000,1000000 --reps 10 --slab lanes
  done
}

suite_overhead() {
  run $bin bench overhead --nodes 1000 --elements 256 --reps 50
}

for s in "${want[@]}"; do
  echo "######## suite $s" | tee -a "$log"
  "suite_$s"
done
exit 0

#!/usr/bin/env bash
# The batched backend's checks and figures on a CUDA GPU, in one run (docs/batch.md, "Figures").
#
#     pip install -e ".[batch]"          # plus torch for the training run
#     bash scripts/gpu_checks.sh [OUT]   # OUT: output folder (default surgsim-out/gpu_checks)
#
# 1. the CUDA tests: one world on the GPU against the CPU Simulation, Grasp-v0 and Slippage-v0 on the GPU,
#    and the physics replayed as CUDA graphs against plain launches (bit for bit);
# 2. surgsim bench batch on cuda: Palpation-v0 at 1, 256, 4,096 and 16,384 worlds and Grasp-v0 at 1, 256 and
#    4,096, device outputs, CUDA graphs on; Palpation-v0 at 4,096 with graphs off (the launch cost they save);
# 3. scripts/train_batched.py: PPO on 4,096 worlds of Palpation-v0 for 100 iterations (skipped without torch).
# Each step's log and the benches' JSON, tables and charts go to OUT; a summary is printed last.
# About 10 minutes on one H100-class GPU (not measured yet: this project's hosts have none).
set -u -o pipefail
OUT=${1:-surgsim-out/gpu_checks}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
PY=${PYTHON:-python3}
status=0

run() {  # run NAME CMD...: log to OUT/NAME.log, keep going on failure
  local name=$1; shift
  echo "== $name: $*"
  if "$@" > "$OUT/$name.log" 2>&1; then echo "   ok"; else echo "   FAILED (see $OUT/$name.log)"; status=1; fi
}

{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || echo "no nvidia-smi"; } \
  > "$OUT/gpu.txt" 2>&1
$PY -c "import warp as wp; wp.init(); print('warp', wp.__version__, 'cuda devices', wp.get_cuda_device_count())" \
  >> "$OUT/gpu.txt" 2>&1
cat "$OUT/gpu.txt"

run tests $PY -m pytest -q -p no:cacheprovider -m "" \
  "tests/test_batch_equivalence.py::test_one_world_on_cuda_matches_the_cpu_simulation" \
  "tests/test_batch_step_graph.py::test_cuda_graph_replays_the_same_steps" \
  tests/test_batch_grasp_env.py tests/test_batch_slippage_env.py
run bench_palpation $PY -m surgsim_envs.cli bench batch --device cuda --worlds 1,256,4096,16384 --outputs device \
  --steps 20 --repeats 3 --graphs on --json --out "$OUT/palpation"
run bench_palpation_no_graphs $PY -m surgsim_envs.cli bench batch --device cuda --worlds 4096 --outputs device \
  --steps 20 --repeats 3 --graphs off --json --out "$OUT/palpation_no_graphs"
run bench_grasp $PY -m surgsim_envs.cli bench batch --device cuda --task SurgSim/Grasp-v0 --worlds 1,256,4096 \
  --outputs device --steps 10 --repeats 3 --graphs on --json --out "$OUT/grasp"
if $PY -c "import torch, sys; sys.exit(0 if torch.cuda.is_available() else 1)" 2>/dev/null; then
  run train $PY scripts/train_batched.py --device cuda --worlds 4096 --iterations 100 --out "$OUT/train"
else
  echo "== train: skipped (torch with CUDA is not installed)"
fi

echo
echo "summary ($OUT):"
for f in palpation palpation_no_graphs grasp; do
  [ -f "$OUT/$f/batch_speed.md" ] && { echo "-- $f"; cat "$OUT/$f/batch_speed.md"; }
done
[ -f "$OUT/train/curve.csv" ] && { echo "-- train (last rows of curve.csv)"; tail -3 "$OUT/train/curve.csv"; }
exit $status

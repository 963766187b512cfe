#!/usr/bin/env bash
# One-shot GPU measurement of the jax backend (`exact` on leaf-box certified neighbours): 2 and 8
# parts at 1,000 points a part, 64 checkpoints each, then 20 parts, 8 checkpoints in calls of 8
# (7.5 s a checkpoint on an H200): cold and warm seconds per checkpoint, the per-stage split
# (leaf boxes, ICP, part CDs, host), the share of queries the leaves did not certify,
# agreement with numba on the first checkpoints of each, and the projection to 60,000
# checkpoints. Its two halves took 2.5 min (H100) and 2.7 min (H200) in the runs that docs/performance.md
# records (a fresh machine compiles the numba kernels first). Writes bench_jax_gpu.json and bench_jax_gpu_20parts.json in
# benchmarks/results (or $1) and prints them.
#
# Run from the repository root on the GPU machine, with the project's pure-Python imports that
# a bare CUDA/JAX image may lack carried as wheels in .whl/ (downloaded beforehand, elsewhere):
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl \
#     trimesh==5.2.0 orjson==3.13.0 pydantic==2.14.4 pydantic_core==2.50.5 annotated-types==0.8.0 typing-inspection==0.4.5
#   bash benchmarks/device_jax.sh [OUT_DIR]
set -euo pipefail
out_dir="${1:-benchmarks/results}"
export PYTHONPATH="$PWD"
if compgen -G ".whl/*.whl" > /dev/null; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/aw_site .whl/*.whl
  export PYTHONPATH="/tmp/aw_site:$PWD"
fi
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
python3 -c "import jax; print('jax', jax.__version__, jax.devices())"
nvidia-smi --query-gpu=name,memory.total --format=csv,noheader || true
timeout 300 python3 benchmarks/bench_jax.py --parts 2 8 --n-fps 1000 --checkpoints 64 --chunk 32 --numba 4 \
  --out "$out_dir" --name bench_jax_gpu
timeout 240 python3 benchmarks/bench_jax.py --parts 20 --n-fps 1000 --checkpoints 8 --chunk 8 --numba 2 \
  --out "$out_dir" --name bench_jax_gpu_20parts

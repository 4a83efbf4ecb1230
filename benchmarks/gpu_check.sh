#!/usr/bin/env bash
# Every on-device check of the GPU kernel in one run, for a machine with an NVIDIA GPU and no network:
#
#     bash benchmarks/gpu_check.sh [OUT]          (OUT defaults to $OUT, else ./gpu-check)
#
# 1. The environment: the machine's own python3 (with numba, numba-cuda, SciPy, PyTorch); the packages it lacks
#    come as wheels in .whl/ (pydantic and its parts, colour-demosaicing; NumPy below 2.5 only where numba-cuda
#    does not import beside the machine's own NumPy), installed into a folder on PYTHONPATH, the package itself
#    from src/ (nothing installed into the machine's Python).
# 2. The GPU tests on the device (CMOSNOISE_TEST_GPU=1: test_cuda at 1920 x 1080, DLPack with PyTorch).
# 3. benchmarks/bench_gpu.py: every preset's bits at 1080p, the multi-plan batch, the speeds, the training
#    crops and the data set's samples beside the CPU's, written to OUT/gpu_speed.json.
#
# Each step has a time limit of its own, so one that hangs leaves the others their time; every log is in OUT.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-${OUT:-gpu-check}}
mkdir -p "$OUT"
export PYTHONUNBUFFERED=1
# one numba cache for the tests and the benchmark: the CPU kernel compiles once
export NUMBA_CACHE_DIR=${NUMBA_CACHE_DIR:-/tmp/cmosnoise-numba-cache}
SITE=/tmp/cmosnoise-site
if ls .whl/*.whl >/dev/null 2>&1; then
  others=$(ls .whl/*.whl | grep -v '/numpy-')
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" $others
fi
export PYTHONPATH="$SITE:$PWD/src"
# numba-cuda 0.30 overloads np.row_stack, which NumPy 2.5 no longer has: it imports, then fails at the first use
if ! python3 -c "import numpy, sys; sys.exit(tuple(map(int, numpy.__version__.split('.')[:2])) >= (2, 5))" \
    && ls .whl/numpy-*.whl >/dev/null 2>&1; then
  echo "NumPy $(python3 -c 'import numpy; print(numpy.__version__)') is too new for numba-cuda 0.30: the carried one"
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE-numpy" .whl/numpy-*.whl
  export PYTHONPATH="$SITE-numpy:$PYTHONPATH"
fi
{
  nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
  python3 -c "import sys, numpy, numba, scipy; from importlib.metadata import version as v
print(sys.version.split()[0], 'numpy', numpy.__version__, 'numba', numba.__version__, 'numba-cuda', v('numba-cuda'),
      'scipy', scipy.__version__)
import numba.cuda as c; print('cuda available:', c.is_available()); c.detect()"
  nproc
  python3 -c "import cmosnoise.model.sensor, cmosnoise.engine.frame.cuda_kernel; print('cmosnoise imports')"
} 2>&1 | tee "$OUT/environment.txt"

echo "== GPU tests (CMOSNOISE_TEST_GPU=1)"
CMOSNOISE_TEST_GPU=1 timeout 200 python3 -m pytest -q -o addopts="" -p no:cacheprovider -x --durations=5 \
  tests/test_cuda.py tests/test_dlpack.py \
  tests/test_flicker_in_time.py::test_the_gpu_gives_the_cpus_bits_with_offsets_that_change_from_frame_to_frame \
  2>&1 | tee "$OUT/gpu_tests.log"
echo "gpu tests exit: ${PIPESTATUS[0]}" | tee -a "$OUT/gpu_tests.log"

echo "== bench_gpu.py"
timeout 330 python3 benchmarks/bench_gpu.py ${BENCH_ARGS:---quick} --json "$OUT/gpu_speed.json" 2>&1 | tee "$OUT/bench_gpu.log"
echo "bench_gpu exit: ${PIPESTATUS[0]}" | tee -a "$OUT/bench_gpu.log"

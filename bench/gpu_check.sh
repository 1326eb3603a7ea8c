#!/usr/bin/env bash
# The GPU check (issue 34), for a bare GPU machine with a CUDA PyTorch and no network: installs gsplat from carried
# wheels, builds its CUDA extension (timed), runs the CUDA tests (gsplat conformance, the fused ADE on CUDA), trains
# and evaluates eigs+ and edi-3dgs on a bundle of chair's prepared artifacts on CUDA, and writes gpu_check.json
# (conformance, PSNR per run, time per step and per run, GPU, torch/gsplat versions, the differences to the committed
# CPU baseline bench/gpu_check_cpu_baseline.json) plus the log, the JUnit XML and the runs' train logs to --out.
#
# Usage (from the repository root): bash bench/gpu_check.sh --bundle .gpu_bundle --out "$OUT"
#   [--wheels .whl] [--runs eigs+,edi-3dgs] [--threads 1] [--skip-tests] [--skip-runs]
# The bundle: `make gpu-bundle` (bench/gpu_check.py bundle); the wheels: `make gpu-wheels`. docs/benchmarks.md
# "GPU path". Our package is used from src/ (PYTHONPATH), so its CPU-only torch pin is never installed; the
# machine's python3 (or $PYTHON) provides torch, numpy, h5py, scipy, scikit-image, opencv, pyyaml and tqdm.
set -uo pipefail

usage() { echo "usage: bash bench/gpu_check.sh --bundle DIR --out DIR [--wheels DIR] [--runs A,B] [--threads N] [--skip-tests] [--skip-runs]"; }
die() { echo "gpu_check.sh: error: $*" >&2; exit 2; }

FAILED="" BUNDLE="" OUTDIR="" WHEELS=".whl" RUNS="eigs+,edi-3dgs" THREADS=1 SKIP_TESTS=0 SKIP_RUNS=0
while [ $# -gt 0 ]; do
    case "$1" in
        --bundle) [ $# -ge 2 ] || die "--bundle needs a folder"; BUNDLE="$2"; shift 2 ;;
        --out) [ $# -ge 2 ] || die "--out needs a folder"; OUTDIR="$2"; shift 2 ;;
        --wheels) [ $# -ge 2 ] || die "--wheels needs a folder"; WHEELS="$2"; shift 2 ;;
        --runs) [ $# -ge 2 ] || die "--runs needs a comma-separated list"; RUNS="$2"; shift 2 ;;
        --threads) [ $# -ge 2 ] || die "--threads needs a number"; THREADS="$2"; shift 2 ;;
        --skip-tests) SKIP_TESTS=1; shift ;;
        --skip-runs) SKIP_RUNS=1; shift ;;
        -h|--help) usage; exit 0 ;;
        *) usage >&2; die "unknown argument '$1'" ;;
    esac
done
[ -n "$BUNDLE" ] || die "--bundle is required"
[ -n "$OUTDIR" ] || die "--out is required"
[ -f "$BUNDLE/MANIFEST.json" ] || die "--bundle: $BUNDLE/MANIFEST.json does not exist (make gpu-bundle)"
[[ "$THREADS" =~ ^[1-9][0-9]*$ ]] || die "--threads must be a positive integer, got '$THREADS'"
[ -f bench/gpu_check.py ] && [ -d src/eigs ] || die "run from the repository root (bench/gpu_check.py, src/eigs)"

REPO=$(pwd)
BUNDLE=$(cd "$BUNDLE" && pwd)
mkdir -p "$OUTDIR" || die "cannot create --out $OUTDIR"
OUTDIR=$(cd "$OUTDIR" && pwd)
PY=${PYTHON:-python3}
WORK=${GPU_CHECK_WORK:-/tmp/gpu_check}
SITE="$WORK/site"
LOG="$OUTDIR/gpu_check.log"
JUNIT="$OUTDIR/junit.xml"
RUNS_JSON="$OUTDIR/runs.json"  # in --out: a check cut short still returns the runs it finished
exec > >(tee -a "$LOG") 2>&1
t_start=$(date +%s)
stamp() { echo "== gpu_check $(date -u +%H:%M:%S) (+$(( $(date +%s) - t_start )) s): $*"; }

stamp "bundle $BUNDLE; out $OUTDIR; python $($PY -c 'import sys; print(sys.version.split()[0])')"
export PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1
"$PY" bench/gpu_check.py verify --bundle "$BUNDLE" || die "the bundle does not verify"

# --- gsplat (and any other missing package) from the carried wheels; nothing is downloaded -------------------------
mkdir -p "$SITE"
if compgen -G "$WHEELS/*.whl" > /dev/null; then
    stamp "installing $(ls "$WHEELS"/*.whl | xargs -n1 basename | tr '\n' ' ')"
    "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$SITE" "$WHEELS"/*.whl \
        || die "pip could not install the wheels of $WHEELS"
else
    stamp "no wheels in $WHEELS: using what $PY already has"
fi
export PYTHONPATH="$SITE:$REPO/src:$REPO${PYTHONPATH:+:$PYTHONPATH}"
export EIGS_CACHE_DIR="$WORK/cache" TORCH_EXTENSIONS_DIR="$WORK/torch_extensions"
export TORCH_CUDA_ARCH_LIST=${TORCH_CUDA_ARCH_LIST:-9.0} MAX_JOBS=${MAX_JOBS:-16}
if [ -z "${CUDA_HOME:-}" ]; then
    # torch guesses the toolkit root from nvcc's folder, which a wrapper script misleads (no -lcudart at link time)
    for c in /usr/local/cuda "$(dirname "$(dirname "$(readlink -f "$(command -v nvcc || echo /nonexistent/bin/nvcc)")")")"; do
        if [ -x "$c/bin/nvcc" ]; then export CUDA_HOME="$c"; break; fi
    done
fi
stamp "CUDA_HOME=${CUDA_HOME:-unset} TORCH_CUDA_ARCH_LIST=$TORCH_CUDA_ARCH_LIST MAX_JOBS=$MAX_JOBS"
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || true
"$PY" -c "import torch, gsplat; print('torch', torch.__version__, 'cuda', torch.version.cuda, 'gpu', torch.cuda.is_available() and torch.cuda.get_device_name(0), 'gsplat', gsplat.__version__)" \
    || stamp "torch/gsplat import failed"

# --- gsplat's CUDA extension: JIT build on first use (needs nvcc and ninja), timed --------------------------------
stamp "building gsplat's CUDA extension"
t0=$(date +%s.%N)
if "$PY" -c "from gsplat.cuda._backend import _C; assert _C is not None, 'gsplat has no CUDA extension (no CUDA toolkit found)'"; then
    BUILD_S=$("$PY" -c "print(round($(date +%s.%N) - $t0, 1))")
    stamp "gsplat built in $BUILD_S s"
else
    BUILD_S=""
    stamp "gsplat's build FAILED"
    FAILED="${FAILED}gsplat-build "
fi

report() {
    "$PY" bench/gpu_check.py report --junit "$JUNIT" ${TESTS_RC:+--tests-rc "$TESTS_RC"} \
        ${BUILD_S:+--gsplat-build-s "$BUILD_S"} $( [ -f "$RUNS_JSON" ] && echo --runs-json "$RUNS_JSON" ) \
        $( [ -f bench/gpu_check_cpu_baseline.json ] && echo --baseline bench/gpu_check_cpu_baseline.json ) \
        -o "$OUTDIR/gpu_check.json"
}

# --- the CUDA tests (they skip without CUDA; a skip is not a pass in the report) -----------------------------------
TESTS_RC=""
if [ "$SKIP_TESTS" = 0 ]; then
    stamp "CUDA tests"
    timeout 240 "$PY" -m pytest -p no:cacheprovider -p no:xdist -q -rA --junitxml="$JUNIT" \
        tests/render/test_gsplat_conformance.py "tests/train/test_ade.py::test_fused_on_cuda_equals_cpu_reference"
    TESTS_RC=$?
    stamp "CUDA tests exited $TESTS_RC"
    [ "$TESTS_RC" = 0 ] || FAILED="${FAILED}tests "
fi
report

# --- the suite's runs on CUDA, then the report ---------------------------------------------------------------------
if [ "$SKIP_RUNS" = 0 ]; then
    rm -f "$RUNS_JSON"
    "$PY" bench/gpu_check.py run --bundle "$BUNDLE" --device cuda --runs "$RUNS" --threads "$THREADS" \
        --work "$WORK/runs" -o "$RUNS_JSON"
    rc=$?
    stamp "runs exited $rc"
    [ "$rc" = 0 ] || FAILED="${FAILED}runs "
    for d in "$WORK"/runs/*/; do
        [ -f "$d/train_log.csv" ] && cp "$d/train_log.csv" "$OUTDIR/$(basename "$d")_train_log.csv"
    done
    tail -n 40 "$WORK"/runs/logs/*.log > "$OUTDIR/runs_tail.log" 2>/dev/null  # the eigs commands' own logs
fi
report || FAILED="${FAILED}report "
cat "$OUTDIR/gpu_check.json"
# exit status: 0 when every phase that ran succeeded (a conformance skip fails pytest's JUnit check in the report,
# not here); 1 otherwise, naming the phases
if [ -n "$FAILED" ]; then stamp "done; FAILED: $FAILED"; exit 1; fi
stamp "done"

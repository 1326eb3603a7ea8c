#!/usr/bin/env bash
# One call of the 16-core device machine for issue 32 (docs/benchmarks.md "How the cost grows", docs/results.md
# "DAVIS346-like scenes"): (A) the training step's cost over threads and image sizes on one DAVIS346-like scene
# (bench/cost.py steps; at most $A_LIMIT seconds), then (B) the jobs of a bench/device_batch.py bundle made with
# --edi-on-machine, $WORKERS jobs of $THREADS threads at a time, none started after $START_UNTIL s, all stopped at
# $DEADLINE s (counted from the start of B). Our package runs from src/ on the machine's own python3 (its torch).
#
# Usage (repository root): bash bench/device_d346.sh DIR OUT
#   DIR: bundle/ (device_batch.py bundle ... --edi-on-machine ...), resources/ (lpips/, brisque/), whl/ (plyfile)
#   OUT: cost_device.jsonl, batch.tgz (device_batch.py --pack), batch.json, lscpu.txt, the log
set -uo pipefail
[ $# -eq 2 ] || { echo "usage: bash bench/device_d346.sh DIR OUT" >&2; exit 2; }
DIR=$(cd "$1" && pwd) || exit 2
OUT=$2
mkdir -p "$OUT" && OUT=$(cd "$OUT" && pwd) || exit 2
W=${D346_WORK:-/tmp/d346}
SCENE=${COST_SCENE:-d346-dish}
exec > >(tee -a "$OUT/device_d346.log") 2>&1
t0=$(date +%s)
stamp() { echo "== device_d346 $(date -u +%H:%M:%S) (+$(( $(date +%s) - t0 )) s): $*"; }

python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site "$DIR"/whl/*.whl \
    || { echo "device_d346.sh: pip could not install $DIR/whl" >&2; exit 2; }
export PYTHONPATH="/tmp/site:$PWD/src:$PWD" PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1 EIGS_CACHE_DIR="$W/cache"
mkdir -p "$W"
lscpu > "$OUT/lscpu.txt" 2>&1
stamp "python $(python3 -c 'import sys, torch; print(sys.version.split()[0], "torch", torch.__version__)')"

# (A) the EDI file of the cost scene, as rules/edi.smk makes it, then the step timings (the rasterizer builds here)
EDI_CONFIG=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['edi'][sys.argv[2]]['edi'])" \
    "$DIR/bundle/MANIFEST.json" "$SCENE")
stamp "A: eigs edi $SCENE"
python3 -m eigs.cli edi "$DIR/bundle/$SCENE/scene.h5" -o "$W/a/edi.h5" --latent-dir "$W/a/latent" --bins 4 \
    --config "$EDI_CONFIG" --threads 16 > "$OUT/a_edi.log" 2>&1 || stamp "A: eigs edi failed"
stamp "A: step cost"
timeout "${A_LIMIT:-100}" python3 bench/cost.py steps --results "$DIR/bundle/$SCENE" --edi "$W/a/edi.h5" \
    --config config/davis346.yaml --runs 3dgs,eigs+ --sizes 346x260,800x800 --gaussians 20000 \
    --threads 16,8,4,2,1 --repeats 3 -o "$OUT/cost_device.jsonl"
stamp "A: done ($?)"

# (B) the jobs
python3 bench/device_batch.py run --bundle "$DIR/bundle" --resources "$DIR/resources" --work "$W/batch" \
    --workers "${WORKERS:-8}" --threads "${THREADS:-2}" --start-until "${START_UNTIL:-330}" \
    --deadline "${DEADLINE:-440}" --pack "$OUT/batch.tgz"
cp "$W/batch/batch.json" "$OUT/batch.json" 2>/dev/null
stamp "B: done"

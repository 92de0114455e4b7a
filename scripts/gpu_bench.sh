#!/usr/bin/env bash
# CUDA figures in one run on a fresh, offline GPU machine:
#
#   scripts/gpu_bench.sh OUTDIR            (needs .wheelhouse/ from scripts/wheelhouse.sh 3.12)
#   scripts/gpu_bench.sh --local OUTDIR    (the same steps on llvm_ad_rgb at tiny sizes, with a
#                                           wheelhouse built for this machine's Python)
#
# Installs the wheelhouse offline (`pip install --no-index`) over the host Python, prints the GPU and
# driver, then runs each step under its own time limit (one failing step does not stop the
# others): Ray reordering at 1024² and 2048², per-stage overhead (at 1024² and 2048², images on the
# device, and once copied to host), Table 1, one equal-time
# study cell, the gradient step at 1024², and the test suite on the CUDA variant. Results go
# to OUTDIR: each benchmark's JSON, steps.csv, reorder.csv, summary.json and summary.md (one
# page: device, driver, each step's status and time, key figures). Each step has its own time
# limit, and a deadline for the whole run (default 470 s, for 8 minutes with the install) caps
# them. Scenes the wheelhouse carries (scenes/*.tar.xz) are unpacked into ../shared/scenes.
#
# Environment: PYTHON (default python3.12, else python3), WHEELHOUSE_DIR (.wheelhouse),
# GPU_BENCH_VENV (install folder; default a fresh temporary one), GPU_BENCH_SYSTEM_SITE (1, the
# default: the wheels go into a folder put first on PYTHONPATH, so the host Python's own
# packages, such as a CUDA image's NumPy, scikit-image and pytest, fill what the wheelhouse
# left out (see WHEELHOUSE_HOST_HAS); 0: a fresh isolated venv), GPU_BENCH_VARIANT (cuda_ad_rgb),
# GPU_BENCH_DEADLINE (seconds for the whole run, default 470), GPU_BENCH_TESTS (pytest
# targets, default tests), GPU_BENCH_PARITY_TESTS (run first: the backend-parity and kernel-budget
# tests), GPU_BENCH_MAXFAIL (25), GPU_BENCH_ONLY (step names to run, e.g. "overhead tests_parity";
# install, scenes and variant always run; default every step but the opt-in "vr" and "stereo"),
# GPU_BENCH_OVERHEAD_CASES and GPU_BENCH_OVERHEAD_CASES_2X (bench_overhead's cases at 1024² and 2048²), GPU_BENCH_OVERHEAD_ARGS
# (more bench_overhead arguments, e.g. --no-freeze).
set -u
cd "$(dirname "$0")/.."
ROOT=$(pwd)

LOCAL=0
if [ "${1:-}" = "--local" ]; then LOCAL=1; shift; fi
if [ $# -ne 1 ] || [ -z "$1" ] || [ "${1#-}" != "$1" ]; then
  echo "gpu_bench: give one output folder (usage: scripts/gpu_bench.sh [--local] OUTDIR)" >&2
  exit 2
fi
mkdir -p "$1/logs" || { echo "gpu_bench: OUTDIR '$1' cannot be created" >&2; exit 2; }
OUT=$(cd "$1" && pwd)
WH=${WHEELHOUSE_DIR:-.wheelhouse}
START=$(date +%s)
DEADLINE=$((START + ${GPU_BENCH_DEADLINE:-470}))
STEPS=$OUT/steps.csv
echo "step,status,seconds,limit_s,note" > "$STEPS"

if [ $LOCAL = 1 ]; then
  VARIANT=${GPU_BENCH_VARIANT:-llvm_ad_rgb}
  S1=64; S2=96; SB=32; ST1=64; SCELL=32; REPEATS=1; OSCALE=0.0625; OSCALE2=0.125; RFRAC=0.35
  TESTS=${GPU_BENCH_TESTS:-tests/test_sampling.py}
  PARITY=${GPU_BENCH_PARITY_TESTS:-tests/test_backend_parity.py}
  [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && [ -f .venv/llvm-path ] && export DRJIT_LIBLLVM_PATH=$(cat .venv/llvm-path)
else
  VARIANT=${GPU_BENCH_VARIANT:-cuda_ad_rgb}
  S1=1024; S2=2048; SB=1024; ST1=2048; SCELL=1024; REPEATS=2; OSCALE=1; OSCALE2=2; RFRAC=0.10
  TESTS=${GPU_BENCH_TESTS:-tests}
  PARITY=${GPU_BENCH_PARITY_TESTS:-tests/test_backend_parity.py tests/test_kernel_budget.py}
fi
export FOVEATED_MI_VARIANT=$VARIANT
if [ -z "${PYTHON:-}" ]; then
  if [ $LOCAL = 0 ] && command -v python3.12 >/dev/null 2>&1; then PYTHON=python3.12; else PYTHON=python3; fi
fi
VENV=${GPU_BENCH_VENV:-$(mktemp -d "${TMPDIR:-/tmp}/foveated_mi_bench.XXXXXX")/venv}
VPY=$VENV/bin/python

log() { echo "gpu_bench: $*"; }

# step NAME LIMIT_S NOTE CMD...: run CMD under `timeout` (capped by the deadline), log to
# logs/NAME.log, record status and time in steps.csv.
step() {
  local name=$1 limit=$2 note=$3; shift 3
  if [ -n "${GPU_BENCH_ONLY:-}" ] && [ "$name" != install ] && [ "$name" != scenes ] \
     && [ "$name" != variant ] && [[ " $GPU_BENCH_ONLY " != *" $name "* ]]; then
    echo "$name,skipped,0,$limit,not in GPU_BENCH_ONLY" >> "$STEPS"
    log "$name: skipped (not in GPU_BENCH_ONLY)"; return 0
  fi
  local left=$((DEADLINE - $(date +%s)))
  if [ $left -lt 5 ]; then
    echo "$name,skipped,0,$limit,no time left before the deadline" >> "$STEPS"
    log "$name: skipped (no time left before the deadline)"; return 0
  fi
  [ $limit -gt $left ] && limit=$left
  local t0; t0=$(date +%s.%N)
  timeout -k 10 "$limit" "$@" > "$OUT/logs/$name.log" 2>&1
  local rc=$?
  local dt; dt=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  local status=ok
  if [ $rc = 124 ] || [ $rc = 137 ]; then status=timeout; elif [ $rc != 0 ]; then status="failed (exit $rc)"; fi
  [ "$status" = ok ] || note="$note; last line: $(tail -n 1 "$OUT/logs/$name.log" | tr ',\n' '; ' | cut -c1-200)"
  echo "$name,$status,$dt,$limit,$note" >> "$STEPS"
  log "$name: $status in ${dt} s (limit $limit s)"
  return 0
}

skip() {  # skip NAME REASON
  echo "$1,skipped,0,0,$2" >> "$STEPS"
  log "$1: skipped ($2)"
}

have_modules() {  # have_modules MOD...: prints the missing ones, status 1 if any
  local out rc
  out=$("$VPY" -c 'import importlib.util as u, sys
m = [x for x in sys.argv[1:] if u.find_spec(x) is None]
print(" ".join(m)); sys.exit(1 if m else 0)' "$@" 2>/dev/null); rc=$?
  if [ $rc -gt 1 ] || { [ $rc != 0 ] && [ -z "$out" ]; }; then echo "$* (no working venv)"; return 1; fi
  echo "$out"; return $rc
}

install() {
  local whl=("$WH"/*.whl)
  [ -e "${whl[0]}" ] || { echo "no wheels in $WH: run scripts/wheelhouse.sh first" >&2; return 1; }
  if [ "${GPU_BENCH_SYSTEM_SITE:-1}" = 1 ]; then
    # An overlay on the host Python rather than a venv: a venv made from a venv's Python (as
    # on CUDA images) would see the base install's packages, not that venv's.
    local py site=$VENV/site; py=$(command -v "$PYTHON") || { echo "no $PYTHON" >&2; return 1; }
    mkdir -p "$VENV/bin" "$site"
    if "$py" -m pip --version >/dev/null 2>&1; then
      "$py" -m pip install -q --disable-pip-version-check --no-index --no-deps --target "$site" "${whl[@]}" || return 1
    else
      echo "pip unavailable: unpacking the wheels into $site"
      for w in "${whl[@]}"; do "$py" -m zipfile -e "$w" "$site" || return 1; done
    fi
    printf '#!/bin/sh\nPATH="%s/bin:$PATH" PYTHONPATH="%s${PYTHONPATH:+:$PYTHONPATH}" exec "%s" "$@"\n' \
      "$site" "$site" "$py" > "$VPY"
    chmod +x "$VPY"; return 0
  fi
  if "$PYTHON" -m venv "$VENV" 2>/dev/null && "$VPY" -m pip --version >/dev/null 2>&1; then
    "$VPY" -m pip install -q --disable-pip-version-check --no-index --find-links "$WH" --no-deps "${whl[@]}"
  else
    # No ensurepip (e.g. python3-venv missing): unpack the wheels into a bare venv.
    rm -rf "$VENV"; "$PYTHON" -m venv --without-pip "$VENV" || return 1
    local site; site=$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    echo "pip unavailable: unpacking the wheels into $site"
    for w in "${whl[@]}"; do "$VPY" -m zipfile -e "$w" "$site" || return 1; done
  fi
}

log "output: $OUT; variant $VARIANT; python $PYTHON; wheelhouse $WH; venv $VENV"
export WH VENV VPY PYTHON
step install 90 "pip install --no-index of $WH" bash -c "$(declare -f install); install"
# Scenes the wheelhouse carries go where the benchmarks look for them (../shared/scenes).
if ls "$WH"/scenes/*.tar.xz >/dev/null 2>&1; then
  step scenes 60 "unpack $WH/scenes into ../shared/scenes" bash -c '
    d=$0/../shared/scenes; mkdir -p "$d" || exit 1
    for a in "$1"/scenes/*.tar.xz; do n=$(basename "$a" .tar.xz)
      if [ -f "$d/$n/scene.xml" ]; then echo "$n: already there"; else tar -C "$d" -xJf "$a" && echo "$n: unpacked"; fi
    done' "$ROOT" "$WH"
fi
"$VPY" -c 'import sys; print(sys.version.split()[0])' > "$OUT/python.txt" 2>/dev/null || echo "?" > "$OUT/python.txt"

if command -v nvidia-smi >/dev/null 2>&1; then
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader > "$OUT/gpu.txt" 2>&1
  nvidia-smi > "$OUT/logs/nvidia-smi.log" 2>&1
else
  echo "none (nvidia-smi not found)" > "$OUT/gpu.txt"
fi
log "GPU, driver, memory: $(head -n 1 "$OUT/gpu.txt")"

step variant 60 "mi.set_variant($VARIANT)" "$VPY" -c "
import mitsuba as mi, drjit as dr
mi.set_variant('$VARIANT')
print(mi.variant(), mi.__version__, dr.__version__)"

B=benchmarks
step reorder_$S1 45 "bench_reorder $S1² (every mode)" "$VPY" $B/bench_reorder.py \
  --size $S1 $S1 --fraction $RFRAC --variant "$VARIANT" --frames 5 --warmup 2 --out "$OUT/reorder_$S1.json"
step reorder_$S2 60 "bench_reorder $S2² (every mode)" "$VPY" $B/bench_reorder.py \
  --size $S2 $S2 --fraction $RFRAC --variant "$VARIANT" --frames 3 --warmup 1 --out "$OUT/reorder_$S2.json"

if [ -f $B/bench_overhead.py ]; then
  # Every case whose scene is here (a case without its scene is skipped with a line).
  CASES=${GPU_BENCH_OVERHEAD_CASES:-voxel-static voxel-moving staircase-guided staircase-oidn voxel-static-vr voxel-moving-vr staircase-vr table1-rungholt table1-vokselia table1-eye-exam}
  [ $LOCAL = 1 ] && CASES=${GPU_BENCH_OVERHEAD_CASES:-voxel-static}
  step overhead 120 "bench_overhead (per-stage table: $CASES)" "$VPY" $B/bench_overhead.py \
    --cases $CASES --scale $OSCALE ${GPU_BENCH_OVERHEAD_ARGS:-} --out "$OUT/overhead.json"
  # The paper's frame size (2048²): on a GPU a 1024² frame is launch-bound.
  CASES2=${GPU_BENCH_OVERHEAD_CASES_2X:-voxel-static voxel-moving voxel-static-vr voxel-moving-vr table1-rungholt table1-vokselia table1-eye-exam}
  [ $LOCAL = 1 ] && CASES2=${GPU_BENCH_OVERHEAD_CASES_2X:-voxel-static}
  step overhead_2x 90 "bench_overhead at twice the size ($CASES2)" "$VPY" $B/bench_overhead.py \
    --cases $CASES2 --scale $OSCALE2 --frames 3 --warmup 2 ${GPU_BENCH_OVERHEAD_ARGS:-} \
    --out "$OUT/overhead_2x.json"
  # The same still frame with every image copied to host memory, as a program that saves it does.
  step overhead_2x_host 30 "bench_overhead voxel-static at twice the size, images copied to host" \
    "$VPY" $B/bench_overhead.py --cases voxel-static --scale $OSCALE2 --frames 3 --warmup 2 \
    --to-host --out "$OUT/overhead_2x_host.json"
else
  skip overhead "benchmarks/bench_overhead.py not in this tree"
fi

STUDY_MODULES=(skimage colour flip_evaluator tqdm)
if missing=$(have_modules "${STUDY_MODULES[@]}"); then
  step table1 150 "paper_table1 study at $ST1²" "$VPY" -c \
    'import sys; from foveated_mi.cli import main; sys.exit(main(sys.argv[1:]))' study \
    configs/studies/paper_table1.toml --size $ST1 $ST1 --variant "$VARIANT" --out "$OUT/table1" --no-progress
else
  # The study also measures quality (needs $missing); the timing columns of Table 1 come
  # from bench_reorder on its scenes at the paper's ray fractions (0.29M and 0.14M of 4.19M).
  step table1_eye_exam 30 "Table 1 timing only (no $missing): bench_reorder eye-exam $ST1² at 6.9 % rays" \
    "$VPY" $B/bench_reorder.py --scene eye-exam --size $ST1 $ST1 --fraction 0.069 --max-depth 8 \
    --variant "$VARIANT" --frames 3 --warmup 1 --out "$OUT/table1_eye_exam.json"
  step table1_voxel_city 30 "Table 1 timing only (no $missing): bench_reorder voxel-city $ST1² at 3.3 % rays" \
    "$VPY" $B/bench_reorder.py --scene voxel-city --size $ST1 $ST1 --fraction 0.033 --max-depth 8 \
    --variant "$VARIANT" --frames 3 --warmup 1 --out "$OUT/table1_voxel_city.json"
fi

step backward_$SB 50 "bench_backward --sizes $SB" "$VPY" $B/bench_backward.py --sizes $SB \
  --repeats $REPEATS --out "$OUT/backward_$SB.json"

if missing=$(have_modules "${STUDY_MODULES[@]}"); then
  step equal_time_cell 40 "equal-time cell (configs/studies/equal_time_cell.toml) at $SCELL²" "$VPY" -c \
    'import sys; from foveated_mi.cli import main; sys.exit(main(sys.argv[1:]))' study \
    configs/studies/equal_time_cell.toml --size $SCELL $SCELL --variant "$VARIANT" \
    --out "$OUT/equal_time_cell" --no-progress
else
  skip equal_time_cell "the study's quality metrics need $missing (not in the wheelhouse)"
fi

# The VR study at the size it was written for (1152x648 across 100 degrees, 54 frames at 90 Hz,
# 256-spp references per frame), voxel-city, one seed: opt-in (GPU_BENCH_ONLY="vr"), as it
# needs most of a run's deadline. Without torch in the wheelhouse it scores fovea PSNR only.
if [[ " ${GPU_BENCH_ONLY:-} " == *" vr "* ]]; then
  if missing=$(have_modules "${STUDY_MODULES[@]}"); then
    step vr 420 "VR study (configs/studies/vr.toml), voxel-city, seed 0" "$VPY" -m foveated_mi.cli \
      study report configs/studies/vr.toml --variant "$VARIANT" --seeds 0 --scenes voxel-city --out "$OUT/vr" \
      --results "$OUT/vr/results" --no-progress
  else
    skip vr "the study's quality metrics need $missing (not in the wheelhouse)"
  fi
else
  skip vr "opt-in: GPU_BENCH_ONLY=\"vr\""
fi

# A headset's two eyes against one eye and uniform stereo, frame cost at its whole eye buffer
# (Quest 3, then Varjo XR-4): opt-in (GPU_BENCH_ONLY="stereo").
if [[ " ${GPU_BENCH_ONLY:-} " == *" stereo "* ]]; then
  EW=0; [ $LOCAL = 1 ] && EW=48
  step stereo 120 "bench_stereo_frame quest3 and varjo_xr4, whole eye buffer (--eye-width $EW)" \
    bash -c 'for hs in quest3 varjo_xr4; do echo "== $hs"; "$0" "$1"/bench_stereo_frame.py \
      --headset $hs --eye-width "$2" --variant "$3" --out "$4/stereo_$hs.json" || exit 1; done' \
    "$VPY" "$B" "$EW" "$VARIANT" "$OUT"
else
  skip stereo "opt-in: GPU_BENCH_ONLY=\"stereo\""
fi

if missing=$(have_modules pytest); then
  # What can differ on the device first (a few seconds), then the whole suite in the time left
  # (on a cold CUDA kernel cache it needs more than 2 minutes: every test compiles kernels).
  PYTEST=(env PYTHONPATH="$ROOT/scripts" "$VPY" -m pytest -q -p no:cacheprovider -p _offline_pytest
          --maxfail="${GPU_BENCH_MAXFAIL:-25}")
  step tests_parity 90 "pytest $PARITY on $VARIANT" "${PYTEST[@]}" --junitxml="$OUT/tests_parity.xml" $PARITY
  step tests 120 "pytest $TESTS on $VARIANT" "${PYTEST[@]}" --junitxml="$OUT/tests.xml" $TESTS
else
  skip tests "pytest is not in the wheelhouse"
fi

log "total $(( $(date +%s) - START )) s"
"$PYTHON" scripts/_bench_summary.py "$OUT" --variant "$VARIANT" 2>"$OUT/logs/summary.log" \
  || log "summary failed: see $OUT/logs/summary.log"
[ -f "$OUT/summary.md" ] && cat "$OUT/summary.md"
if grep -q -e ",failed" -e ",timeout," "$STEPS"; then exit 1; fi
exit 0

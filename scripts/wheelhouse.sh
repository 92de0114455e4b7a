#!/usr/bin/env bash
# Offline wheelhouse for a CUDA machine: scripts/wheelhouse.sh [PYVER]   (default 3.12)
#
# Builds .wheelhouse/ (git-ignored) with everything `pip install --no-index` needs on a
# manylinux x86-64 machine with CPython PYVER and no network: Mitsuba slimmed to the
# cuda_ad_rgb and llvm_ad_rgb variants, Dr.Jit, NumPy (without its tests), the project's own
# wheel, then, each group only if it still fits, the benchmark extras (tqdm, FLIP), the study
# metrics (colour-science, OpenEXR, scikit-image), the test runner (pytest, hypothesis) and
# Intel OIDN (pyoidn). The working tree plus the wheelhouse must stay within CAP_MIB (64 MiB):
# the script prints the sizes and what it left out, and fails with one line when even the
# required group does not fit.
#
# Environment: WHEELHOUSE_DIR (default .wheelhouse), CAP_MIB (default 64), PYTHON (the Python
# that runs pip; default .venv/bin/python, else python3), WHEELHOUSE_PLATFORM (default
# manylinux x86-64), WHEELHOUSE_HOST_HAS (distributions the target's Python already has, such
# as "numpy scikit-image pytest hypothesis" on a CUDA image with PyTorch: they are left out,
# which leaves room for the rest; gpu_bench.sh's venv sees the host's packages). Needs the
# package registry (run it where the network is).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

PYVER=${1:-3.12}
if ! [[ $PYVER =~ ^3\.[0-9]+$ ]]; then
  echo "wheelhouse: PYVER '$PYVER' is not allowed; give a CPython version like 3.12" >&2
  exit 2
fi
WH=${WHEELHOUSE_DIR:-.wheelhouse}
CAP_MIB=${CAP_MIB:-64}
if [ -z "${PYTHON:-}" ]; then
  if [ -x .venv/bin/python ]; then PYTHON=.venv/bin/python; else PYTHON=python3; fi
fi
PLATFORMS=(${WHEELHOUSE_PLATFORM:-manylinux_2_28_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64})
HELPER="$PYTHON $ROOT/scripts/_wheelhouse.py"
norm() { echo "$1" | tr 'A-Z_.' 'a-z--'; }
HOST_HAS=" "; HH=${WHEELHOUSE_HOST_HAS:-}; for n in ${HH//,/ }; do HOST_HAS+="$(norm "$n") "; done
host_has() { [[ $HOST_HAS == *" $(norm "$1") "* ]]; }

STAGE=$(mktemp -d "${TMPDIR:-/tmp}/wheelhouse.XXXXXX")
trap 'rm -rf "$STAGE"' EXIT

download() {  # download DEST [pip args...]: binary wheels for the target, resolved for it
  local dest=$1; shift
  local plat=(); for p in "${PLATFORMS[@]}"; do plat+=(--platform "$p"); done
  "$PYTHON" -m pip download -q --disable-pip-version-check --only-binary=:all: "${plat[@]}" \
    --python-version "$PYVER" --implementation cp -d "$dest" "$@"
}

mb() { awk -v b="$1" 'BEGIN { printf "%.1f MiB", b / 1048576 }'; }
bytes() { local t=0 f; for f in "$@"; do t=$((t + $(stat -c %s "$f"))); done; echo $t; }

echo "wheelhouse: CPython $PYVER, ${PLATFORMS[*]}, into $WH (cap $CAP_MIB MiB with the working tree)"
[ "$HOST_HAS" = " " ] || echo "wheelhouse: the target already has:$HOST_HAS(left out)"
rm -rf "$WH.part"; mkdir -p "$WH.part"

# Required group: what every benchmark imports.
mkdir -p "$STAGE/mi"
download "$STAGE/mi" --no-deps "mitsuba==3.9.1" "drjit==1.5.0"
$HELPER slim "$STAGE"/mi/mitsuba-*.whl "$WH.part"
cp "$STAGE"/mi/drjit-*.whl "$WH.part/"
if ! host_has numpy; then
  mkdir -p "$STAGE/numpy"
  download "$STAGE/numpy" "numpy>=1.24"
  $HELPER strip-tests "$STAGE"/numpy/numpy-*.whl "$WH.part"   # NumPy's own test suite: 1.5 MB
fi
# The project's own wheel (its other dependencies are installed from this folder or skipped:
# gpu_bench.sh installs with --no-deps). Built in a copy so that no build/ lands in the tree.
mkdir -p "$STAGE/src"
git ls-files -z --cached --others --exclude-standard | xargs -0 cp --parents -t "$STAGE/src" 2>/dev/null || true
"$PYTHON" -m pip wheel -q --disable-pip-version-check --no-deps -w "$WH.part" "$STAGE/src" >/dev/null

TREE=$($HELPER tree-bytes "$ROOT")
CAP=$((CAP_MIB * 1048576))
if ! $HELPER cap --repo "$ROOT" --wheelhouse "$WH.part" --cap-mib "$CAP_MIB"; then
  exit 1
fi

# Optional groups, in order of use; each is added whole or left out.
add_group() {  # add_group [--strip] NAME PIP-ARGS... (requirements the target already has are dropped)
  local strip=0; [ "$1" = --strip ] && { strip=1; shift; }
  local name=$1; shift
  local args=() a reqs=0
  for a in "$@"; do
    if [[ $a != -* ]]; then host_has "${a%%[<>=!~;]*}" && continue; reqs=$((reqs + 1)); fi
    args+=("$a")
  done
  [ $reqs -gt 0 ] || { echo "wheelhouse: $name: the target already has it"; return 0; }
  set -- "${args[@]}"
  local d="$STAGE/g-$name"; mkdir -p "$d"
  if ! download "$d" "$@" 2>"$STAGE/err-$name"; then
    echo "wheelhouse: $name: left out (download failed: $(tail -n 1 "$STAGE/err-$name"))"
    return 0
  fi
  if [ $strip = 1 ]; then  # tests and stray coverage reports out, RECORD rewritten
    mkdir -p "$d/stripped"; for f in "$d"/*.whl; do $HELPER strip-tests "$f" "$d/stripped" >/dev/null; done
    d=$d/stripped
  fi
  local new=()
  for f in "$d"/*.whl; do [ -e "$WH.part/$(basename "$f")" ] || new+=("$f"); done
  [ ${#new[@]} -gt 0 ] || { echo "wheelhouse: $name: already in"; return 0; }
  local add; add=$(bytes "${new[@]}")
  local have; have=$(bytes "$WH.part"/*.whl)
  if [ $((TREE + have + add)) -le $CAP ]; then
    cp "${new[@]}" "$WH.part/"
    echo "wheelhouse: $name: included ($(mb "$add"))"
  else
    echo "wheelhouse: $name: left out ($(mb "$add") would pass the cap by $(mb $((TREE + have + add - CAP))))"
  fi
}
add_group "benchmark extras (tqdm, flip-evaluator)" "tqdm>=4.66" "flip-evaluator>=1.7"
# colour-science and OpenEXR need only NumPy, which is in already.
add_group --strip "study metrics (colour-science, OpenEXR)" --no-deps "colour-science>=0.4.4" "OpenEXR>=3.2"
add_group "scikit-image (study metrics)" "scikit-image>=0.22"
add_group "test runner (pytest, hypothesis)" "pytest>=8,<8.4" "hypothesis>=6.100"
add_group "pyoidn (Intel OIDN denoiser)" --no-deps "pyoidn>=2.5"

# The shared scenes the benchmarks use, as scenes/NAME.tar.xz (gpu_bench.sh unpacks each where
# the benchmarks look, ../shared/scenes beside the tree), smallest first, each if it fits.
SCENES=${WHEELHOUSE_SCENES:-$ROOT/../shared/scenes}
if [ -d "$SCENES" ]; then
  mkdir -p "$WH.part/scenes"
  for s in $(cd "$SCENES" && du -s -- */ 2>/dev/null | sort -n | awk '{ print $2 }'); do
    s=${s%/}; [ -f "$SCENES/$s/scene.xml" ] || continue
    tar -C "$SCENES" -cJf "$STAGE/$s.tar.xz" "$s"
    add=$(bytes "$STAGE/$s.tar.xz"); have=$(du -sb "$WH.part" | cut -f1)
    if [ $((TREE + have + add)) -le $CAP ]; then
      mv "$STAGE/$s.tar.xz" "$WH.part/scenes/"; echo "wheelhouse: scene $s: included ($(mb "$add"))"
    else
      echo "wheelhouse: scene $s: left out ($(mb "$add") would pass the cap by $(mb $((TREE + have + add - CAP))))"
    fi
  done
fi

rm -rf "$WH"; mv "$WH.part" "$WH"
HAVE=$(du -sb "$WH" | cut -f1)
(cd "$WH" && find . -type f | sed 's|^\./|  |' | sort)
echo "wheelhouse: $(ls "$WH"/*.whl | wc -l) wheels and $(ls "$WH"/scenes/*.tar.xz 2>/dev/null | wc -l) scenes, $(mb "$HAVE"); working tree $(mb "$TREE"); total $(mb $((TREE + HAVE))) of $CAP_MIB MiB"

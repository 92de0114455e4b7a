#!/usr/bin/env bash
# One-step environment for foveated_mi: .venv, the package, and an LLVM >= 16 for Dr.Jit.
# Called by `make demo` / `make test`; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}

find_python() {
  for py in "${PYTHON:-}" python3.13 python3.12 python3.11 python3.10 python3; do
    [ -n "$py" ] || continue
    if command -v "$py" >/dev/null 2>&1 && "$py" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null; then
      echo "$py"; return 0
    fi
  done
  return 1
}

find_llvm() {
  # Dr.Jit 1.5 aborts on LLVM 15 (fminimum lowering); accept 16 or newer.
  local v f
  for v in 21 20 19 18 17 16; do
    for f in /usr/lib/x86_64-linux-gnu/libLLVM.so.$v.1 /usr/lib/x86_64-linux-gnu/libLLVM-$v.so \
             /usr/lib/aarch64-linux-gnu/libLLVM.so.$v.1 /usr/lib/aarch64-linux-gnu/libLLVM-$v.so \
             /usr/lib/llvm-$v/lib/libLLVM.so /usr/lib/llvm-$v/lib/libLLVM-$v.so /usr/lib64/libLLVM-$v.so \
             /opt/homebrew/opt/llvm/lib/libLLVM.dylib /usr/local/opt/llvm/lib/libLLVM.dylib; do
      [ -e "$f" ] && { echo "$f"; return 0; }
    done
  done
  return 1
}

PY=$(find_python) || { echo "foveated_mi setup: needs Python >= 3.10 (none found on PATH); install python3 and python3-venv." >&2; exit 1; }

if [ -n "${DRJIT_LIBLLVM_PATH:-}" ] && [ -e "$DRJIT_LIBLLVM_PATH" ]; then
  LLVM=$DRJIT_LIBLLVM_PATH
elif ! LLVM=$(find_llvm); then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "foveated_mi setup: installing libllvm19 (Dr.Jit needs LLVM >= 16)"
    DEBIAN_FRONTEND=noninteractive apt-get update -qq
    APT_UPDATED=1
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null
    LLVM=$(find_llvm) || { echo "foveated_mi setup: libllvm19 installed but libLLVM.so.19 not found" >&2; exit 1; }
  else
    echo "foveated_mi setup: Dr.Jit needs LLVM >= 16; install it (Debian/Ubuntu: sudo apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH." >&2
    exit 1
  fi
fi

# The live view's browser tests drive Debian's chromium through chromedriver (selenium).
# Optional: without them those tests skip, saying why.
if [ -x /usr/bin/chromium ] && [ -x /usr/bin/chromedriver ]; then
  :
elif [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "foveated_mi setup: installing chromium and chromium-driver (the live view's browser tests)"
  { [ -n "${APT_UPDATED:-}" ] || DEBIAN_FRONTEND=noninteractive apt-get update -qq; } &&
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1 ||
    echo "foveated_mi setup: chromium could not be installed; the live view's browser tests will skip" >&2
else
  echo "foveated_mi setup: no chromium/chromedriver and not root: the live view's browser tests will skip (sudo apt-get install chromium chromium-driver)"
fi

if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV" || { echo "foveated_mi setup: '$PY -m venv' failed; install python3-venv." >&2; exit 1; }
fi
"$VENV/bin/python" -m pip install -q --upgrade pip
"$VENV/bin/python" -m pip install -q -e '.[test]' --config-settings editable_mode=compat
echo "$LLVM" > "$VENV/llvm-path"
touch "$VENV/.installed"
echo "foveated_mi setup: ready ($VENV, DRJIT_LIBLLVM_PATH=$LLVM)"

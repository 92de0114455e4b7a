#!/usr/bin/env bash
# The perceptual extra (FovVideoVDP: pyfvvdp and PyTorch) in the venv, for `make test-perceptual`.
# PyTorch goes in first, as a CPU build: left to `pip install -e '.[perceptual]'`, a plain torch
# requirement pulls the CUDA build (several GB) on Linux. TORCH_SPEC is what pip is given for it
# (default torch==2.13.0); it may carry pip options, e.g. where no CPU wheel is at hand:
#   TORCH_SPEC="torch --index-url https://download.pytorch.org/whl/cpu" make test-perceptual
# Called by `make test-perceptual`; safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
TORCH_SPEC=${TORCH_SPEC:-torch==2.13.0}

if [ ! -x "$VENV/bin/python" ]; then
  echo "foveated_mi setup: no virtual environment at $VENV; run 'make setup' first." >&2
  exit 1
fi
set -f                          # TORCH_SPEC splits into words (options) but never globs
# shellcheck disable=SC2086
"$VENV/bin/python" -m pip install -q $TORCH_SPEC
set +f
"$VENV/bin/python" -m pip install -q -e '.[perceptual]' --config-settings editable_mode=compat
"$VENV/bin/python" -c 'import pyfvvdp, torch' || {
  echo "foveated_mi setup: pyfvvdp or torch does not import in $VENV after installing the perceptual extra." >&2
  exit 1
}
touch "$VENV/.perceptual"
echo "foveated_mi setup: perceptual extra ready ($VENV, torch $("$VENV/bin/python" -c 'import torch; print(torch.__version__)'))"

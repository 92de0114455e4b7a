#!/usr/bin/env python3
"""Execute the notebooks in ``notebooks/`` in place, keeping their outputs.

    python scripts/run_notebooks.py                 # small size (128), quick look
    python scripts/run_notebooks.py --full          # each notebook's full size (paper sizes)
    python scripts/run_notebooks.py --size 256 paper_table1 speed_accuracy

The size reaches a notebook through ``FOVEATED_MI_NB_SIZE`` (unset with ``--full``); study
results go to ``out/notebooks/<study>-<size>`` (``FOVEATED_MI_NB_OUT`` overrides), so a rerun
resumes a study instead of recomputing it.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
NOTEBOOKS = ("quickstart", "paper_fig9", "paper_fig7_quality", "paper_table1",
             "speed_accuracy", "inverse_rendering")
SMALL = 128


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*", help=f"notebooks to run (default: all of "
                   f"{', '.join(NOTEBOOKS)})")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--full", action="store_true", help="each notebook's full size")
    g.add_argument("--size", type=int, default=SMALL, help=f"film side (default {SMALL})")
    p.add_argument("--timeout", type=int, default=24 * 3600, help="seconds per cell")
    a = p.parse_args(argv)
    names = a.names or list(NOTEBOOKS)
    for n in names:
        if n not in NOTEBOOKS:
            p.error(f"notebook = {n!r} is invalid: expected one of {', '.join(NOTEBOOKS)}")
    if not a.full and a.size < 1:
        p.error(f"--size = {a.size} is invalid: expected an integer >= 1")
    import nbformat
    from nbclient import NotebookClient

    if a.full:
        os.environ.pop("FOVEATED_MI_NB_SIZE", None)
    else:
        os.environ["FOVEATED_MI_NB_SIZE"] = str(a.size)
    for name in names:
        path = os.path.join(ROOT, "notebooks", f"{name}.ipynb")
        nb = nbformat.read(path, as_version=4)
        t0 = time.perf_counter()
        NotebookClient(nb, timeout=a.timeout, kernel_name="python3",
                       resources={"metadata": {"path": os.path.dirname(path)}}).execute()
        from foveated_mi.io import atomic_write
        with atomic_write(path, "w", encoding="utf-8") as f:
            nbformat.write(nb, f)
        print(f"{name}: executed in {time.perf_counter() - t0:.0f} s "
              f"({'full size' if a.full else f'size {a.size}'}), saved {path}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

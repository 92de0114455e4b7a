"""Where a cold test run's time goes: the kernels each test compiles, and how many of them
differ from a kernel compiled earlier in the run only in their literal constants (a film size,
a path depth, a threshold), which one shared value would have served from the cache.

As a pytest plugin, it records every test's compiled kernels (Dr.Jit's kernel history: those
not served by the in-memory or the on-disk cache), with their LLVM compile time and a hash of
their IR with every literal replaced by one placeholder::

    export DRJIT_CACHE_DIR=$(mktemp -d)                  # an empty kernel cache: a cold run
    PYTHONPATH=benchmarks python -m pytest -q -p no:cacheprovider -p suite_compile
    python benchmarks/suite_compile.py out/suite_compile.jsonl

Run it in one process (no ``-n``), so that each kernel is compiled once and charged to the
first test that needs it. The report prints the totals and the files that compile most.
"""
from __future__ import annotations

import collections
import hashlib
import json
import os
import re
import sys

#: Where the plugin appends one JSON line per test.
OUT = os.path.join("out", "suite_compile.jsonl")

# An LLVM literal operand (integer, float, hex float, boolean) after its type, and a kernel's
# own name (a hash of its IR).
_LITERAL = re.compile(r"\b(i1|i8|i16|i32|i64|half|float|double)\s+"
                      r"(-?\d+(?:\.\d+)?(?:e[-+]?\d+)?|0x[0-9A-Fa-f]+|true|false)\b")
_NAME = re.compile(r"@drjit_[0-9a-f]+")


def shape_of(ir: str) -> str:
    """A kernel's IR with its name and every literal replaced: equal for kernels that differ
    only in their constants.

    Parameters
    ----------
    ir : str
        The kernel's LLVM IR.

    Returns
    -------
    shape : str
        The MD5 of the normalised IR.
    """
    return hashlib.md5(_LITERAL.sub(r"\1 K", _NAME.sub("@k", ir)).encode()).hexdigest()


# -- the pytest plugin ---------------------------------------------------------------------------

def pytest_runtest_setup(item):
    import drjit as dr
    dr.kernel_history_clear()
    dr.set_flag(dr.JitFlag.KernelHistory, True)


def pytest_runtest_teardown(item, nextitem):
    import drjit as dr
    compiled = [(shape_of(e["ir"].getvalue()), e.get("backend_time", 0.0))
                for e in dr.kernel_history([dr.KernelType.JIT]) if not e.get("cache_hit")]
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "a") as f:
        f.write(json.dumps({"test": item.nodeid, "compiled": compiled}) + "\n")


# -- the report ----------------------------------------------------------------------------------

def tally(path: str) -> dict:
    """The kernels a run recorded by the plugin compiled, in all and per test file.

    Parameters
    ----------
    path : str
        The plugin's JSON lines.

    Returns
    -------
    tally : dict
        ``kernels``, ``compile_s``, ``literal_variants`` (kernels that differ from an earlier
        one only in literals), ``literal_variants_s`` and ``programs`` (distinct ones), and the
        same four per test file under ``files``, the costliest first.
    """
    seen: set[str] = set()
    per_file = collections.defaultdict(lambda: [0, 0.0, 0, 0.0])
    with open(path) as f:
        for line in f:
            row = json.loads(line)
            acc = per_file[row["test"].split("::")[0]]
            for shape, ms in row["compiled"]:
                acc[0] += 1
                acc[1] += ms / 1e3
                if shape in seen:          # the same program as an earlier kernel
                    acc[2] += 1
                    acc[3] += ms / 1e3
                seen.add(shape)
    keys = ("kernels", "compile_s", "literal_variants", "literal_variants_s")
    files = {name: dict(zip(keys, v)) for name, v in
             sorted(per_file.items(), key=lambda kv: -kv[1][1])}
    return {**{k: sum(v[i] for v in per_file.values()) for i, k in enumerate(keys)},
            "programs": len(seen), "files": files}


def report(path: str, top: int = 12) -> str:
    """The totals of a run recorded by the plugin, and the files that compile most.

    Parameters
    ----------
    path : str
        The plugin's JSON lines.
    top : int, optional
        How many files to list.

    Returns
    -------
    text : str
        A Markdown table with a summary line above it.
    """
    t = tally(path)
    lines = [f"{t['kernels']} kernels compiled in {t['compile_s']:.1f} s; "
             f"{t['literal_variants']} of them ({t['literal_variants_s']:.1f} s) differ from an "
             f"earlier one only in literals; {t['programs']} distinct programs "
             f"({t['compile_s'] - t['literal_variants_s']:.1f} s).", "",
             "| file | kernels | compile s | literal variants | their s |", "|---|---|---|---|---|"]
    for name, f in list(t["files"].items())[:top]:
        lines.append(f"| {name} | {f['kernels']} | {f['compile_s']:.1f} | "
                     f"{f['literal_variants']} | {f['literal_variants_s']:.1f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from common import parser, write_json   # here: the plugin itself stays light
    ap = parser(__doc__, out_help="write the totals, per test file too, to this JSON file")
    ap.add_argument("path", nargs="?", default=OUT, help="the plugin's output")
    ap.add_argument("--top", type=int, default=12, help="files listed (default 12)")
    args = ap.parse_args(argv)
    if not os.path.exists(args.path):
        print(f"path = {args.path!r} is invalid: expected the file the plugin wrote "
              f"(run pytest with -p suite_compile first)", file=sys.stderr)
        return 2
    print(report(args.path, args.top))
    write_json(args.out, tally(args.path))
    return 0


if __name__ == "__main__":
    sys.exit(main())

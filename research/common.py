"""The probes' helpers: the benchmarks' own (``benchmarks/common.py``), read from the
repository's root so that a probe run as ``python research/NAME.py`` finds them."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from benchmarks.common import *  # noqa: E402,F401,F403  (every helper, by its name)

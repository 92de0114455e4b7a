"""The benchmarks of foveated_mi, one suite: ``python -m benchmarks --list`` (see
:mod:`benchmarks.__main__`)."""

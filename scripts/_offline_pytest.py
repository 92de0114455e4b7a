"""pytest plugin for an offline machine that has only part of the test dependencies.

    PYTHONPATH=scripts python -m pytest -p _offline_pytest ...

A test file whose top-level imports name a module that is not installed is not collected, and
a test that fails with ``ModuleNotFoundError`` for a module that is not installed, or with the
project's one-line error for an optional dependency that is missing (``... expected pyoidn
installed ...``), is reported as skipped, naming the module, so that failures left are the ones worth reading. Used by
``scripts/gpu_bench.sh``.
"""
from __future__ import annotations

import ast
import importlib.util
import re

import pytest

_IGNORED: dict[str, list[str]] = {}


def missing_imports(path: str) -> list[str]:
    """Top-level modules imported at the top of ``path`` (outside functions) that are not
    installed."""
    try:
        tree = ast.parse(open(path, encoding="utf-8").read(), path)
    except (OSError, SyntaxError):
        return []
    names = []
    for node in tree.body:
        if isinstance(node, ast.Import):
            names += [a.name.split(".")[0] for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module.split(".")[0])
    return sorted({n for n in names if importlib.util.find_spec(n) is None})


def pytest_ignore_collect(collection_path, config):
    p = str(collection_path)
    if p.endswith(".py") and collection_path.name.startswith("test_"):
        missing = missing_imports(p)
        if missing:
            _IGNORED[collection_path.name] = missing
            return True
    return None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    if call.excinfo is None or not rep.failed:
        return
    name = ""
    if call.excinfo.errisinstance(ModuleNotFoundError):
        name = (getattr(call.excinfo.value, "name", None) or "").split(".")[0]
    elif call.excinfo.errisinstance(ValueError):
        m = re.search(r"expected (\w+) installed", str(call.excinfo.value))
        name = m.group(1) if m else ""
    if name:
        if importlib.util.find_spec(name) is None:
            rep.outcome = "skipped"
            rep.longrepr = (str(item.path), item.location[1] or 0,
                            f"Skipped: needs {name} (not installed here)")


def pytest_terminal_summary(terminalreporter):
    if _IGNORED:
        terminalreporter.write_line("not collected (modules not installed): " + "; ".join(
            f"{f} ({', '.join(m)})" for f, m in sorted(_IGNORED.items())))

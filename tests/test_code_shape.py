"""The shape of the code that later work keeps: no import cycle, no import of the live view
from below it, no function over 60 lines, an integrator that only orchestrates (under 300
lines), no function that takes the options outside the modules that read them into
settings, and a short README: at most 300 lines,
20,000 bytes and 300 characters a line, each table cell within three lines of text (the
figures live in docs/results.md).

Each rule is a plain function of source text, checked first on a small case that breaks it,
so a rule that stopped seeing anything would fail here."""
from __future__ import annotations

import ast
import collections
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "foveated_mi"
#: What a parameter that is the options is annotated as (:func:`is_the_options`): their type,
#: and the mappings that, keyed by name to ``Any``, are what they are.
OPTION_TYPES = ("Options", "Mapping", "MutableMapping")
ANY_MAPPINGS = ("dict", "Dict", "Mapping", "MutableMapping")
#: The modules that read the options into typed settings (or are the options, or make an
#: integrator of them): the only ones whose functions may take them.
OPTION_READERS = ("options.py", "configure.py", "integrators/foveated.py", "budget.py",
                  "render.py", "cli.py")
#: Not a frame's way: the studies' result rows and a file's attributes are named values of
#: any kind (a row holds its run's options as data).
RECORDS = ("study/", "io.py")


def _modules(root: pathlib.Path) -> dict[str, pathlib.Path]:
    mods = {}
    for p in root.rglob("*.py"):
        name = ".".join(p.relative_to(root.parent).with_suffix("").parts)
        mods[name[:-len(".__init__")] if name.endswith(".__init__") else name] = p
    return mods


def import_cycles(sources: dict[str, tuple[str, bool]], deferred: bool = False
                  ) -> list[list[str]]:
    """Cycles among module-level imports (a function-level import is deferred, so it cannot
    close one at import time); with ``deferred``, among every import, in functions and under
    ``TYPE_CHECKING`` too: two modules that each need the other are one module in two files.
    ``sources``: module name -> (its text, whether it is a package's __init__)."""
    graph = collections.defaultdict(set)
    for name, (text, is_pkg) in sources.items():
        pkg = name if is_pkg else name.rpartition(".")[0]
        tree = ast.parse(text)
        for node in ast.walk(tree) if deferred else tree.body:
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = pkg.split(".")
                if node.level > 1:
                    base = base[:len(base) - (node.level - 1)]
                mod = (".".join(base + ([node.module] if node.module else []))
                       if node.level else node.module or "")
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in sources else mod
                           for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            graph[name].update(t for t in targets if t in sources and t != name)
    colour, stack, found = {}, [], []

    def visit(u):
        colour[u] = 1
        stack.append(u)
        for v in sorted(graph[u]):
            if colour.get(v) == 1:
                found.append(stack[stack.index(v):] + [v])
            elif v not in colour:
                visit(v)
        stack.pop()
        colour[u] = 2

    for u in sorted(sources):
        if u not in colour:
            visit(u)
    return found


def long_functions(text: str, limit: int = 60) -> list[tuple[str, int]]:
    """Functions (methods included) longer than ``limit`` lines, with their lengths."""
    return [(n.name, n.end_lineno - n.lineno + 1) for n in ast.walk(ast.parse(text))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
            and n.end_lineno - n.lineno + 1 > limit]


def is_the_options(annotation: ast.expr | None) -> bool:
    """Whether a parameter's annotation says it is the options: their type (``Options``), or
    a mapping of names to anything (``dict[str, Any]``, ``Mapping[str, Any]``, a bare
    ``Mapping``), alone, in a union or a container, or written as a string."""
    if isinstance(annotation, ast.Constant) and isinstance(annotation.value, str):
        annotation = ast.parse(annotation.value, mode="eval").body
    if annotation is None:
        return False
    if isinstance(annotation, ast.Subscript):
        base = ast.unparse(annotation.value).rpartition(".")[2]
        args = getattr(annotation.slice, "elts", [annotation.slice])
        if base in ANY_MAPPINGS and [ast.unparse(e).rpartition(".")[2] for e in args] == [
                "str", "Any"]:
            return True
        return any(is_the_options(e) for e in args)
    if isinstance(annotation, (ast.Name, ast.Attribute)):
        name = annotation.attr if isinstance(annotation, ast.Attribute) else annotation.id
        return name in OPTION_TYPES
    return any(is_the_options(e) for e in ast.iter_child_nodes(annotation)
               if isinstance(e, ast.expr))


def option_takers(text: str) -> list[str]:
    """Functions with a parameter annotated as the options (:func:`is_the_options`)."""
    found = []
    for n in ast.walk(ast.parse(text)):
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = n.args
            params = a.posonlyargs + a.args + a.kwonlyargs + [x for x in (a.vararg, a.kwarg) if x]
            found += [f"{n.name}({x.arg})" for x in params if is_the_options(x.annotation)]
    return found


def test_the_rules_see_what_breaks_them():
    cyclic = {"p": ("", True), "p.a": ("from . import b\n", False),
              "p.b": ("from .a import x\n", False)}
    assert import_cycles(cyclic) == [["p.a", "p.b", "p.a"]]
    deferred = {**cyclic, "p.b": ("def f():\n    from .a import x\n", False)}
    assert import_cycles(deferred) == []
    assert import_cycles(deferred, deferred=True) == [["p.a", "p.b", "p.a"]]
    typing_only = {**cyclic, "p.b": ("if TYPE_CHECKING:\n    from .a import x\n", False)}
    assert import_cycles(typing_only, deferred=True) == [["p.a", "p.b", "p.a"]]
    body = "def f():\n" + "    x = 1\n" * 60
    assert long_functions(body) == [("f", 61)]
    assert long_functions(body, limit=61) == []
    taking = ("def f(width, o: Options):\n    pass\n"
              "def g(a: int, *, b: dict[str, Any] | None = None):\n    pass\n"
              "def h(c: 'typing.Mapping[str, typing.Any]', **d: Mapping):\n    pass\n"
              "def k(e: list[dict[str, Any]]):\n    pass\n")
    assert option_takers(taking) == ["f(o)", "g(b)", "h(c)", "h(d)", "k(e)"]
    # What a parameter is decides, never its name.
    assert option_takers("def f(o: FrameSettings, options: dict[str, int]):\n    pass\n"
                         "def g(settings, stats: dict[str, dr.ArrayBase]):\n    pass\n"
                         "def h(layers: Mapping[str, np.ndarray]):\n    pass\n") == []


def test_no_import_cycle():
    sources = {name: (p.read_text(), p.name == "__init__.py")
               for name, p in _modules(PACKAGE).items()}
    assert len(sources) > 50
    assert import_cycles(sources) == []


def test_no_two_modules_need_each_other_even_deferred():
    """A deferred import breaks a cycle at import time, not in the design: the module that
    both sides need belongs below them."""
    sources = {name: (p.read_text(), p.name == "__init__.py")
               for name, p in _modules(PACKAGE).items()}
    assert import_cycles(sources, deferred=True) == []


def test_no_function_over_sixty_lines():
    found = {f"{p.relative_to(ROOT)}:{name}": n for p in PACKAGE.rglob("*.py")
             for name, n in long_functions(p.read_text())}
    assert found == {}


def test_the_integrator_only_orchestrates():
    lines = (PACKAGE / "integrators" / "foveated.py").read_text().count("\n")
    assert lines < 300, lines


def test_no_pass_takes_the_options():
    """No function of the frame, nor any outside the modules that read the options into
    settings, has a parameter that is the options (``tests/test_frame_inputs.py`` checks
    what the frame's functions receive while they run)."""
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(list((PACKAGE / "frame").rglob("*.py"))) > 20
    found = {p.relative_to(PACKAGE).as_posix(): option_takers(p.read_text()) for p in files}
    assert {k: v for k, v in found.items()
            if v and k not in OPTION_READERS and not k.startswith(RECORDS)} == {}
    # The readers do take them (a rule that saw none would see nothing).
    assert found["configure.py"] and found["options.py"]



def imports_anywhere(name: str, text: str, is_pkg: bool) -> set[str]:
    """Every module that module ``name`` imports, at any depth (a function's imports
    included), as absolute names; ``from a import b`` gives both ``a`` and ``a.b``."""
    pkg = name if is_pkg else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.ImportFrom):
            base = pkg.split(".")[:len(pkg.split(".")) - max(node.level - 1, 0)]
            mod = (".".join(base + ([node.module] if node.module else []))
                   if node.level else node.module or "")
            found |= {mod} | {f"{mod}.{a.name}" for a in node.names}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
    return found


def reaching_into_the_live_view(sources: dict[str, tuple[str, bool]]) -> list[str]:
    """Modules outside ``foveated_mi.live`` and the command line that import the live view."""
    def live(m):
        return m == "foveated_mi.live" or m.startswith("foveated_mi.live.")
    return sorted(n for n, (text, is_pkg) in sources.items()
                  if not live(n) and n != "foveated_mi.cli"
                  and any(live(m) for m in imports_anywhere(n, text, is_pkg)))


def test_only_the_live_view_and_the_command_line_import_the_live_view():
    """The live view is the top floor: the sequence config, the studies and the rest never
    reach up into it (what both need, such as the pose files, lives below)."""
    small = {"foveated_mi": ("from . import live\n", True),
             "foveated_mi.config": ("def f():\n    from .live.poses import P\n", False),
             "foveated_mi.study.spec": ("from ..live import poses\n", False),
             "foveated_mi.paths": ("import foveated_mi.live.renderer\n", False),
             "foveated_mi.cli": ("from .live.server import LiveView\n", False),
             "foveated_mi.live.server": ("from . import protocol\n", False),
             "foveated_mi.sequence": ("from .poses import PoseTrack\n", False)}
    assert reaching_into_the_live_view(small) == [
        "foveated_mi", "foveated_mi.config", "foveated_mi.paths", "foveated_mi.study.spec"]
    sources = {name: (p.read_text(), p.name == "__init__.py")
               for name, p in _modules(PACKAGE).items()}
    assert reaching_into_the_live_view(sources) == []

#: The README's limits: lines, bytes (UTF-8), characters a line, and the visible characters of
#: a table cell (three lines of a column about 65 characters wide).
README_LIMITS = {"lines": 300, "bytes": 20_000, "line": 300, "cell": 200}


def readme_excess(text: str, limits=README_LIMITS) -> list[str]:
    """What in a README's ``text`` is over ``limits``: ``"lines N"``, ``"bytes N"``, ``"line
    K: N"`` and ``"cell K.J: N"`` (line ``K``, column ``J``; link targets are not visible)."""
    out = []
    lines = text.count("\n")
    size = len(text.encode("utf-8"))
    if lines > limits["lines"]:
        out.append(f"lines {lines}")
    if size > limits["bytes"]:
        out.append(f"bytes {size}")
    for k, line in enumerate(text.splitlines(), 1):
        if len(line) > limits["line"]:
            out.append(f"line {k}: {len(line)}")
        if line.startswith("|") and not line.startswith("|--"):
            for j, cell in enumerate(line.strip().strip("|").split(" | "), 1):
                shown = len(re.sub(r"\]\([^)]*\)", "]", cell.strip()))
                if shown > limits["cell"]:
                    out.append(f"cell {k}.{j}: {shown}")
    return out


def test_the_readme_check_sees_each_excess():
    small = {"lines": 3, "bytes": 60, "line": 30, "cell": 8}
    assert readme_excess("# t\n| a | b |\n", small) == []
    text = "# title\n| a | a cell too long |\n" + "x" * 31 + "\n[l](a/very/long/target)\n"
    assert readme_excess(text, small) == ["lines 4", "bytes 88", "cell 2.2: 15",
                                          "line 3: 31"]
    assert readme_excess("| [ok](a/very/long/target) |\n", small) == []


def test_the_readme_stays_short():
    assert readme_excess((ROOT / "README.md").read_text(encoding="utf-8")) == []

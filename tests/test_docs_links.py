"""Links into the documentation keep working: every ``docs/...md#anchor`` that a source, config,
notebook or document names resolves to a heading of that file (GitHub's anchors, duplicates'
``-1`` suffixes included), and every relative link of the README and of ``docs/`` points to a
file that exists (and, for a Markdown file with an anchor, to one of its headings); a link out
of the repository is not checked, as a clone need not have what lies beside it.

Each check is a plain function of a folder, first run on a small tree that breaks it, so a
checker that stopped seeing links would fail here."""
from __future__ import annotations

import functools
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: The files whose text may name a documentation anchor.
SUFFIXES = (".py", ".md", ".toml", ".ipynb")
#: Folders that hold no source of the project (environments, outputs, caches).
SKIP_DIRS = {"out", "build", "dist", "node_modules", "__pycache__"}
#: ``docs/<path>.md#anchor`` anywhere in a text, read from the repository root.
ROOTED = re.compile(r"(?<![\w./-])(docs/[\w./-]*?\.md)#([\w-]*)")
#: A Markdown link or image target: ``](target)``.
MD_LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")


def slug(heading: str) -> str:
    """GitHub's anchor of a heading's text: links and code marks reduced to their text,
    lowercase, every character but letters, digits, ``_``, ``-`` and spaces dropped, spaces
    made ``-``."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = re.sub(r"<[^>]+>", "", text).replace("`", "").lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(text: str) -> set[str]:
    """The anchors of a Markdown text's headings (outside code fences); the n-th repeat of an
    anchor gets ``-n``, as on GitHub."""
    seen: dict[str, int] = {}
    out = set()
    fenced = False
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            continue
        m = None if fenced else HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def _files(root: pathlib.Path, suffixes=SUFFIXES):
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).parts
        if (p.suffix in suffixes and p.is_file()
                and not any(d.startswith(".") or d in SKIP_DIRS or d.endswith(".egg-info")
                            for d in rel[:-1])):
            yield p


def broken_links(root: pathlib.Path, skip=()) -> list[str]:
    """``FILE: TARGET (why)`` for each documentation link under ``root`` that does not resolve:
    a ``docs/...md#anchor`` in any source, config, notebook or document (read from ``root``),
    and a relative link in ``README.md`` or a Markdown file under ``docs/`` (read from its
    file's folder). Files in ``skip`` are not read."""

    @functools.lru_cache(maxsize=None)
    def anchors_of(path: pathlib.Path) -> frozenset[str] | None:
        return frozenset(anchors(path.read_text(encoding="utf-8"))) if path.is_file() else None

    def check(where: pathlib.Path, target: pathlib.Path, anchor: str | None, shown: str):
        rel = where.relative_to(root)
        if not target.exists():
            return [f"{rel}: {shown} (no such file)"]
        if anchor is not None and target.suffix == ".md" and anchor not in anchors_of(target):
            return [f"{rel}: {shown} (no heading with that anchor)"]
        return []

    bad = []
    for p in (f for f in _files(root) if f not in skip):
        text = p.read_text(encoding="utf-8")
        for path, anchor in set(ROOTED.findall(text)):
            bad += check(p, root / path, anchor, f"{path}#{anchor}")
    docs = [root / "README.md", *_files(root / "docs", (".md",))]
    for p in (d for d in docs if d.is_file()):
        for target in set(MD_LINK.findall(p.read_text(encoding="utf-8"))):
            if re.match(r"[a-z]+:", target):
                continue                    # a web address, mailto: ...
            path, _, anchor = target.partition("#")
            dest = (p.parent / path).resolve() if path else p
            if not dest.is_relative_to(root.resolve()):
                continue                    # beside the repository: not in a clone
            bad += check(p, dest, anchor if "#" in target else None, target)
    return sorted(set(bad))


def _tree(tmp_path, files: dict[str, str]) -> pathlib.Path:
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text, encoding="utf-8")
    return tmp_path


def test_anchors_follow_github_rules():
    text = ("# Measured figures\n## Equal time in a headset: the `vr` preset\n"
            "### SVGF's colour test where the camera moved\n## What the periphery flickers at "
            "10-20° while the head turns\n## The VR study at 8.4 pixels per degree\n"
            "```\n# not a heading\n```\n## Frame time\n## Frame time\n## Frame time\n")
    assert anchors(text) == {
        "measured-figures", "equal-time-in-a-headset-the-vr-preset",
        "svgfs-colour-test-where-the-camera-moved",
        "what-the-periphery-flickers-at-10-20-while-the-head-turns",
        "the-vr-study-at-84-pixels-per-degree", "frame-time", "frame-time-1", "frame-time-2"}


def test_the_checker_finds_each_kind_of_broken_link(tmp_path):
    root = _tree(tmp_path, {
        "docs/results.md": "# Figures\n## Frame time\n## Frame time\n[log](log/old.md#gone)\n"
                           "[data](results/missing.json)\n",
        "docs/log/old.md": "# Record\n## Kept\n",
        "pkg/mod.py": '"""See docs/results.md#frame-time-1 and docs/results.md#frame-timing,\n'
                      'wrapped: docs/results.md#the-"\n"disc."""\n',
        "configs/a.toml": "# docs/results.md#frame-time; docs/missing.md#x\n",
        "README.md": "[ok](docs/results.md#frame-time) [img](docs/live.png) "
                     "[beside](../shared/scenes/README.md)\n",
    })
    assert broken_links(root) == [
        "README.md: docs/live.png (no such file)",
        "configs/a.toml: docs/missing.md#x (no such file)",
        "docs/results.md: log/old.md#gone (no heading with that anchor)",
        "docs/results.md: results/missing.json (no such file)",
        "pkg/mod.py: docs/results.md#frame-timing (no heading with that anchor)",
        "pkg/mod.py: docs/results.md#the- (no heading with that anchor)",
    ]
    # Renaming the heading breaks the link that named it; naming it back mends it.
    (root / "docs/log/old.md").write_text("# Record\n## Gone\n", encoding="utf-8")
    assert "docs/results.md: log/old.md#gone (no heading with that anchor)" \
        not in broken_links(root)


def test_every_documentation_link_resolves():
    # This file's own examples of broken links are not links.
    assert broken_links(ROOT, skip={pathlib.Path(__file__).resolve()}) == []

"""The commands the documents quote name what exists: every ``foveated-mi VERB ...`` names a
verb of the command line (``study`` then an analysis verb or a study file that exists), and
every ``python benchmarks/NAME.py`` or ``python research/NAME.py`` a script that exists.

Each check is a plain function of a text, first run on a small text that breaks it, so a
checker that stopped seeing commands would fail here."""
from __future__ import annotations

import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
#: The documents whose commands a reader copies.
DOCS = ("README.md", "docs/results.md", "docs/studies.md")
#: ``foveated-mi`` and the words after it, up to a flag (or a pipe, a quote, the line's end).
CLI = re.compile(r"(?<![\w/-])foveated-mi((?: +[\w./$<>][\w./$<>-]*)*)")
#: ``python folder/NAME.py``.
SCRIPT = re.compile(r"python (benchmarks|research)/([\w-]+)\.py")


def bad_commands(text: str, root: pathlib.Path = ROOT) -> list[str]:
    """The commands of ``text`` that name no verb or script of the repository at ``root``."""
    from foveated_mi import cli
    verbs = set(cli.build_parser()._subparsers._group_actions[0].choices)
    bad = []
    for m in SCRIPT.finditer(text):
        if not (root / m.group(1) / f"{m.group(2)}.py").is_file():
            bad.append(m.group(0))
    for m in CLI.finditer(text):
        words = m.group(1).split()
        if not words or words[0].startswith("-"):
            continue                            # the program named in prose
        if words[0] not in verbs:
            bad.append(m.group(0))
        elif words[0] == "study" and len(words) > 1 and not words[1].startswith("-"):
            if words[1] == "inspect":
                if len(words) < 3 or words[2] not in cli.INSPECT_VERBS:
                    bad.append(m.group(0))
            elif words[1] not in cli.STUDY_VERBS and words[1].endswith(".toml") \
                    and "$" not in words[1] and not (root / words[1]).is_file():
                bad.append(m.group(0))
            elif words[1] not in cli.STUDY_VERBS and not words[1].endswith(".toml"):
                bad.append(m.group(0))
    return bad


def test_the_checker_sees_a_missing_verb_script_and_study():
    text = ("foveated-mi render cornell-box\n`foveated-mi study report configs/studies/vr.toml`\n"
            "foveated-mi study inspect where --study x\nfoveated-mi --help\n"
            "python benchmarks/fingerprint.py --out x\n")
    assert bad_commands(text) == []
    broken = ("foveated-mi bench_vr --size 1\nfoveated-mi study repport x\n"
              "foveated-mi study configs/studies/nope.toml\nfoveated-mi study inspect here\n"
              "python benchmarks/bench_vr.py --study x\npython research/nope.py\n")
    assert sorted(bad_commands(broken)) == sorted([
        "python benchmarks/bench_vr.py", "python research/nope.py", "foveated-mi bench_vr",
        "foveated-mi study repport x", "foveated-mi study configs/studies/nope.toml",
        "foveated-mi study inspect here"])


def test_every_command_the_documents_quote_exists():
    for doc in DOCS:
        assert bad_commands((ROOT / doc).read_text()) == [], doc

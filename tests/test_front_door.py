"""The Python front door as the docs show it: every ``bp.NAME`` (and ``bp.NAME.ATTR``) that
README.md and docs/*.md use resolves after ``import baseparams as bp`` alone, in a fresh
interpreter (no other module imported first to make it work by accident)."""

import json
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
NAME = re.compile(r"\bbp\.([A-Za-z_][A-Za-z_0-9]*(?:\.[A-Za-z_][A-Za-z_0-9]*)*)")


def _names_in_docs() -> set[str]:
    names: set[str] = set()
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for match in NAME.finditer(path.read_text(encoding="utf-8")):
            dotted = match.group(1).rstrip(".")
            names.add(dotted)
    return names


def test_every_name_the_docs_use_is_reachable():
    names = sorted(_names_in_docs())
    assert "diagnose" in names and "api.DEFAULT_SOLVER" in names      # the walk finds what it should
    probe = ("import baseparams as bp, json, sys\n"
             "missing = []\n"
             "for dotted in json.loads(sys.argv[1]):\n"
             "    value = bp\n"
             "    for part in dotted.split('.'):\n"
             "        try:\n"
             "            value = getattr(value, part)\n"
             "        except AttributeError:\n"
             "            missing.append(dotted)\n"
             "            break\n"
             "print(json.dumps(missing))\n")
    out = subprocess.run([sys.executable, "-c", probe, json.dumps(names)], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert json.loads(out.stdout) == [], "names the docs use that `import baseparams as bp` does not give"

"""The layering rules of docs/design.md, checked on the source: core never imports from
plugins, ``import baseparams`` loads no plugin, every built-in solver lives under
plugins/solvers/ and satisfies the Solver protocol."""

import ast
import subprocess
import sys
from pathlib import Path

from baseparams import registry
from baseparams.solvers.protocol import Solver

ROOT = Path(__file__).resolve().parents[1]


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
    return out


def test_no_core_module_imports_from_plugins():
    offenders = {str(p.relative_to(ROOT)): sorted(m for m in imported_modules(p) if m.startswith("baseparams.plugins"))
                 for p in (ROOT / "core").rglob("*.py")}
    assert {k: v for k, v in offenders.items() if v} == {}


def test_import_baseparams_loads_no_plugin():
    code = "import sys, baseparams; print(sorted(m for m in sys.modules if m.startswith('baseparams')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "plugins" not in out and "solvers" not in out, out


def test_built_in_solvers_live_under_plugins_solvers_and_keep_the_protocol():
    for name, reg in registry.solvers().items():
        if reg.distribution != "baseparams":
            continue
        solver = reg.item
        assert isinstance(solver, Solver), name
        # plugins/solvers/ is installed as baseparams.plugins.solvers (editable or not)
        assert type(solver).__module__.startswith("baseparams.plugins.solvers."), (name, type(solver).__module__)

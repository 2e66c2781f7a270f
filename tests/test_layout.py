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
    built_in = {name: reg for name, reg in registry.solvers().items() if reg.distribution == "baseparams"}
    assert built_in, "no built-in solver registered: the loop below would check nothing"
    for name, reg in built_in.items():
        solver = reg.item
        assert isinstance(solver, Solver), name
        # plugins/solvers/ is installed as baseparams.plugins.solvers (editable or not)
        assert type(solver).__module__.startswith("baseparams.plugins.solvers."), (name, type(solver).__module__)


def test_the_solver_registry_is_not_empty():
    """The loops above and below pass vacuously on an empty registry: the four built-in
    solvers must be registered (through their entry points, as a third party's)."""
    built_in = {name for name, reg in registry.solvers().items() if reg.distribution == "baseparams"}
    assert {"dp", "vp", "exact", "symbolic"} <= built_in, built_in


# ----- one solver's code lives in its plugin ---------------------------------------------
# The rule: a module-level function or class defined in core/ (the package ``baseparams``)
# that is used by exactly one solver plugin (plugins/solvers/<name>/) and by nothing else
# in core/ or plugins/ belongs in that plugin. "Used" means named in the source: imported
# (``from baseparams.m import f``, relative imports resolved), reached as an attribute of
# an imported module (``certify.f``), or named in its own module outside its definition (a
# core function calling it is core using it). tests/ and benchmarks/ do not count: a test
# may exercise a core helper that only one solver calls, and that alone must not keep it
# in core.

def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    parts = ["baseparams"] + (parts[1:] if parts[0] == "core" else parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _sources() -> dict[str, tuple[str, bool]]:
    """{module: (source text, is a package)} of core/ and plugins/."""
    return {_module_name(p): (p.read_text(encoding="utf-8"), p.name == "__init__.py")
            for top in ("core", "plugins") for p in (ROOT / top).rglob("*.py")}


def _user(module: str) -> str:
    """Who a module is for the rule: "core", "solver:<name>" or "plugin:<name>"."""
    parts = module.split(".")
    if parts[1:3] == ["plugins", "solvers"] and len(parts) > 3:
        return "solver:" + parts[3]
    return "plugin:" + ".".join(parts[2:3]) if parts[1:2] == ["plugins"] else "core"


def _references(module: str, package: str, tree: ast.Module, modules: set[str]) -> set[tuple[str, str]]:
    """(module, name) pairs the source of ``module`` (in ``package``) names (the rule above)."""
    bound: dict[str, str] = {}          # local name -> the module it stands for
    out: set[tuple[str, str]] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name in modules:
                    bound[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            for a in node.names:
                if f"{base}.{a.name}" in modules:
                    bound[a.asname or a.name] = f"{base}.{a.name}"
                else:
                    out.add((base, a.name))
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute):
            chain, inner = [node.attr], node.value
            while isinstance(inner, ast.Attribute):
                chain.append(inner.attr)
                inner = inner.value
            if isinstance(inner, ast.Name):
                owner, _, name = ".".join([bound.get(inner.id, inner.id)] + chain[::-1]).rpartition(".")
                if owner in modules:
                    out.add((owner, name))
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
            out.add((module, node.id))
    return out


def single_solver_core_symbols(sources: dict[str, tuple[str, bool]] | None = None) -> dict[str, str]:
    """{"module.name": "solver:<name>"} for every core symbol that breaks the rule, in
    ``sources`` (default: core/ and plugins/ as they are, :func:`_sources`)."""
    sources = _sources() if sources is None else sources
    modules = set(sources)
    trees = {m: ast.parse(text) for m, (text, _) in sources.items()}
    defined = {(m, node.name) for m, tree in trees.items() if _user(m) == "core"
               for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))}
    users: dict[tuple[str, str], set[str]] = {d: set() for d in defined}
    for m, tree in trees.items():
        package = m if sources[m][1] else m.rpartition(".")[0]
        for ref in _references(m, package, tree, modules):
            if ref in users:
                users[ref].add(_user(m))
    return {f"{m}.{name}": next(iter(who)) for (m, name), who in users.items()
            if len(who) == 1 and next(iter(who)).startswith("solver:")}


# Public helpers made for any solver author (third parties too), which one built-in solver
# happens to be alone in using today: listed with the reason, so the exception is a choice
# (a stale entry fails the test below).
FOR_ANY_SOLVER = {
    "baseparams.solvers.protocol.parameter_count": "an option's maximum (SolverOption(maximum=...))",
    "baseparams.solvers.protocol.last_parameter_index": "an option's maximum (SolverOption(maximum=...))",
    "baseparams.solvers.support.exact_coefficients": "the exact counterpart of decimal_coefficients",
    "baseparams.solvers.support.seconds_text": "the time counterpart of size_text (estimates of long work)",
    "baseparams.dynamics.observation.evaluate_states": "the evaluated samples behind W, for any analysis",
    "baseparams.numeric.linalg.triangular_factor": "W's R folded block by block: any solver's analysis of a W "
                                                   "too tall for memory",
    "baseparams.dynamics.trajectory.samples_per_block": "how many samples of W fit the memory budget at once, "
                                                        "for any solver building W in blocks",
    "baseparams.solvers.support.untrusted_warning": "the warning for values printed beyond their trusted digits, "
                                                    "for any solver that rounds what it prints",
    "baseparams.numeric.decide.rank_estimate": "a float64 estimate of W's rank, for any solver sizing its W "
                                               "by the rank (vp since issue 47)",
}


def test_no_core_symbol_serves_one_solver_only():
    found = single_solver_core_symbols()
    assert {k: v for k, v in found.items() if k not in FOR_ANY_SOLVER} == {}
    assert set(FOR_ANY_SOLVER) <= set(found), "no longer single-solver: drop from FOR_ANY_SOLVER"


def test_the_single_solver_rule_catches_a_helper_left_in_core():
    """The check can fail: vp's own ``balls`` module pretended back in core
    (``baseparams.numeric.balls``, imported so by vp's solver) is reported as vp's alone."""
    sources = _sources()
    text, _ = sources.pop("baseparams.plugins.solvers.vp.balls")
    sources["baseparams.numeric.balls"] = (text, False)
    solver, package = sources["baseparams.plugins.solvers.vp.solver"]
    assert "from . import balls" in solver
    sources["baseparams.plugins.solvers.vp.solver"] = (
        solver.replace("from . import balls", "from baseparams.numeric import balls"), package)
    found = single_solver_core_symbols(sources)
    assert found.get("baseparams.numeric.balls.radius_digits") == "solver:vp", found
    assert found.get("baseparams.numeric.balls.recover_rational") == "solver:vp", found


# functions a few lines over the size rule, on purpose (docs/design.md, "Sizes")
LONG_ON_PURPOSE = {("plugins/solvers/symbolic/elimination.py", "certify"): 110,
                   ("core/excite/collision.py", "_build"): 110}


def test_files_and_functions_stay_small():
    """docs/design.md "Sizes": no file in core/ or plugins/ over 800 lines, no function over 100
    lines but the ones named there."""
    files, functions = [], []
    for path in sorted([*(ROOT / "core").rglob("*.py"), *(ROOT / "plugins").rglob("*.py")]):
        name = str(path.relative_to(ROOT))
        text = path.read_text(encoding="utf-8")
        if text.count("\n") > 800:
            files.append((name, text.count("\n")))
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > LONG_ON_PURPOSE.get((name, node.name), 100):
                    functions.append((name, node.name, length))
    assert files == [] and functions == []

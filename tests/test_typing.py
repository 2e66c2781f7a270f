"""Types: mypy passes on core/ and plugins/ at the level set in pyproject.toml ([tool.mypy]),
and the share of annotated parameters and returns stays at 90 % or more.

The share is counted with ``ast`` over every function and method (lambdas excluded):
a parameter counts when it has an annotation (``self`` and ``cls`` of methods are not
counted; ``*args`` and ``**kwargs`` are), a function's return when it has ``->``.
"""

import ast
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MINIMUM = 0.90

# The folders (below the repository) whose share is asserted and that mypy must pass on.
ASSERTED = ["core", "plugins", "mechanisms"]


def annotation_counts(paths: list[Path]) -> tuple[int, int, int, int]:
    """(annotated parameters, parameters, annotated returns, functions) over ``paths``."""
    params = annotated = returns = functions = 0
    for path in paths:
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        methods = {id(node) for cls in ast.walk(tree) if isinstance(cls, ast.ClassDef)
                   for node in cls.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))}
        for node in ast.walk(tree):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            args = node.args
            positional = args.posonlyargs + args.args
            static = any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in node.decorator_list)
            if id(node) in methods and not static and positional and positional[0].arg in ("self", "cls"):
                positional = positional[1:]
            every = positional + args.kwonlyargs + [a for a in (args.vararg, args.kwarg) if a is not None]
            params += len(every)
            annotated += sum(a.annotation is not None for a in every)
            functions += 1
            returns += node.returns is not None
    return annotated, params, returns, functions


def python_files(target: str) -> list[Path]:
    path = ROOT / target
    return [path] if path.is_file() else sorted(path.rglob("*.py"))


@pytest.mark.parametrize("target", ASSERTED)
def test_annotated_share(target: str) -> None:
    files = python_files(target)
    assert files and all(f.exists() for f in files), f"{target}: no Python file"
    annotated, params, returns, functions = annotation_counts(files)
    assert annotated >= MINIMUM * params, f"{target}: {annotated}/{params} parameters annotated"
    assert returns >= MINIMUM * functions, f"{target}: {returns}/{functions} returns annotated"


def test_overall_share_printed() -> None:
    """The figure over core/ and plugins/ (asserted per folder above, printed here)."""
    annotated, params, returns, functions = annotation_counts(python_files("core") + python_files("plugins"))
    print(f"\ncore/ + plugins/: {annotated}/{params} parameters ({annotated / params:.1%}), "
          f"{returns}/{functions} returns ({returns / functions:.1%}) annotated")
    assert params and functions


def package_tree(into: Path) -> Path:
    """A folder holding ``baseparams/`` as the installed package lays it out (core/ is
    ``baseparams``, plugins/ and mechanisms/ its subpackages), made of links to the
    sources: mypy finds modules by folder names and cannot follow setuptools' package-dir."""
    package = into / "baseparams"
    package.mkdir()
    for entry in (ROOT / "core").iterdir():
        (package / entry.name).symlink_to(entry)
    for sub in ("plugins", "mechanisms"):
        (package / sub).symlink_to(ROOT / sub)
    return into


def source_path(reported: str, root: Path) -> str:
    """``ROOT/baseparams/plugins/urdf/parse.py`` -> ``plugins/urdf/parse.py`` (and core/ for the rest)."""
    inner = reported.removeprefix(f"{root}/").removeprefix("baseparams/")
    return inner if inner.startswith(("plugins/", "mechanisms/")) else "core/" + inner


@pytest.fixture(scope="module")
def mypy_errors(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """mypy's error lines over the whole package, paths as in the repository."""
    api = pytest.importorskip("mypy.api")
    root = package_tree(tmp_path_factory.mktemp("mypy"))
    before = os.environ.get("MYPYPATH")
    os.environ["MYPYPATH"] = str(root)
    try:
        stdout, stderr, status = api.run(["--config-file", str(ROOT / "pyproject.toml"),
                                          "--cache-dir", str(root / ".mypy_cache"), "--no-error-summary",
                                          "--show-error-codes", "-p", "baseparams"])
    finally:
        if before is None:
            del os.environ["MYPYPATH"]
        else:
            os.environ["MYPYPATH"] = before
    assert status in (0, 1), stderr         # 2: mypy itself failed (bad configuration ...)
    errors = [source_path(line, root) for line in stdout.splitlines() if ": error:" in line]
    print(f"\nmypy: {len(errors)} errors over core/, plugins/ and mechanisms/")
    return errors


@pytest.mark.parametrize("target", ASSERTED)
def test_mypy_passes(target: str, mypy_errors: list[str]) -> None:
    """No mypy error in ``target`` at the level set in pyproject.toml ([tool.mypy])."""
    prefix = target if target.endswith(".py") else target + "/"
    mine = [e for e in mypy_errors if e.startswith(prefix)]
    assert not mine, "\n".join(mine)

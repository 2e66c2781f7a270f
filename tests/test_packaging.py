"""Every package of the source tree is installed: pyproject.toml lists its packages by hand
(the tree maps core/ to baseparams), and a new folder missing there installs without it
(after the rooms move, a non-editable install had no baseparams.diagnose)."""

import pathlib
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_every_package_folder_is_listed():
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    found = set()
    for name, folder in setuptools["package-dir"].items():
        for init in (ROOT / folder).rglob("__init__.py"):
            parts = init.parent.relative_to(ROOT / folder).parts
            if "__pycache__" not in parts:
                found.add(".".join([name, *parts]))
    assert found <= listed, f"packages not in pyproject.toml's [tool.setuptools] packages: {sorted(found - listed)}"

"""A third party's distribution adds a joint type through the ``baseparams`` entry points.

The test writes a throwaway distribution ``bp-cylindrical`` (a cylindrical joint ``C``
and its multipole-transfer rule), installs it with pip into a private directory and runs
the command line in a fresh interpreter with that directory on PYTHONPATH, exactly as a
user who ran ``pip install bp-cylindrical`` would. The wheel is assembled here from the
distribution's pyproject.toml, so no build backend (and no network) is needed: a fresh
Python 3.11 venv has setuptools but not ``wheel``, which setuptools < 70.1 needs to build.
"""

import base64
import hashlib
import json
import os
import subprocess
import sys
import tomllib
import zipfile

import pytest

PYPROJECT = """\
[build-system]
requires = ["setuptools>=61"]
build-backend = "setuptools.build_meta"

[project]
name = "bp-cylindrical"
version = "0.1.0"
dependencies = ["baseparams"]

[project.entry-points.baseparams]
cylindrical = "bp_cylindrical.plugin"
"""

PLUGIN = '''\
"""A cylindrical joint: slides along and turns about the frames' common z axis."""

from baseparams.hookspecs import hookimpl
from baseparams.model.joints import JointType
from baseparams.model.multipoles import TransferRule

CYLINDRICAL = JointType(
    name="C", description="cylindrical: translation along z, then rotation about z",
    motions=(("P", "z"), ("R", "z")), suffixes=("s", "theta"),
    closure=(("dot", "z", "x"), ("dot", "z", "y"), ("gap", "x"), ("gap", "y")),
)


@hookimpl
def baseparams_joint_types():
    return [CYLINDRICAL]


@hookimpl
def baseparams_transfer_rules(joint_type):
    if joint_type != "C":
        return None
    # the bodies' angular velocities differ only along z: the axisymmetric quadrupole crosses
    return [TransferRule("quadrupole", (0, 0, 0), (0, 0, 1), 5)]
'''

# A collar on a tilted post (C joint), carrying a pendulum (R joint).
MECHANISM = """\
[mechanism]
name = "collar"

[[bodies]]
label = 1
name = "collar"

[[bodies]]
label = 2
name = "bob"

[[joints]]
name = "post"
type = "C"
parent = 0
child = 1
parent_frame = { point = ["0", "0", "0"], axis = ["0", "0.6", "0.8"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "0", "1"] }

[[joints]]
name = "swing"
type = "R"
parent = 1
child = 2
parent_frame = { point = ["0.2", "0", "0"], axis = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0.3"], axis = ["1", "0", "0"] }
"""


def build_wheel(source, out_dir):
    """A pure-Python wheel of ``source`` (a folder with pyproject.toml and one package)."""
    project = tomllib.loads((source / "pyproject.toml").read_text())["project"]
    name, version = project["name"], project["version"]
    stem = f"{name.replace('-', '_')}-{version}"
    info = f"{stem}.dist-info"
    entry_points = "".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in items.items()) + "\n"
        for group, items in project["entry-points"].items())
    files = {path.relative_to(source).as_posix(): path.read_bytes()
             for path in sorted(source.rglob("*.py"))}
    files[f"{info}/METADATA"] = (f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n"
                                 + "".join(f"Requires-Dist: {d}\n" for d in project["dependencies"])).encode()
    files[f"{info}/WHEEL"] = b"Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n"
    files[f"{info}/entry_points.txt"] = entry_points.encode()
    record = "".join(
        f"{path},sha256={base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b'=').decode()},{len(data)}\n"
        for path, data in files.items()) + f"{info}/RECORD,,\n"
    files[f"{info}/RECORD"] = record.encode()
    wheel = out_dir / f"{stem}-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as archive:
        for path, data in files.items():
            archive.writestr(path, data)
    return wheel


def install_distribution(root, plugin_text):
    """``bp-cylindrical`` with ``plugin_text`` as its plugin module, installed into root/site."""
    source = root / "bp-cylindrical"
    (source / "bp_cylindrical").mkdir(parents=True)
    (source / "pyproject.toml").write_text(PYPROJECT)
    (source / "bp_cylindrical" / "__init__.py").write_text('"""Cylindrical joint for baseparams."""\n')
    (source / "bp_cylindrical" / "plugin.py").write_text(plugin_text)
    wheel = build_wheel(source, root)
    target = root / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "--quiet",
                    "--disable-pip-version-check", "--target", str(target), str(wheel)],
                   check=True, capture_output=True, timeout=600)  # backstops: a loaded machine (issue 46)
    return target


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    return install_distribution(tmp_path_factory.mktemp("third_party"), PLUGIN)


def cli(site, *args):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site)] + [p for p in [env.get("PYTHONPATH")] if p])
    return subprocess.run([sys.executable, "-m", "baseparams.cli", *args], env=env,
                          capture_output=True, text=True, timeout=600)


def test_plugins_lists_the_third_party_joint(site):
    proc = cli(site, "plugins", "--format", "json")
    assert proc.returncode == 0, proc.stderr
    joints = {j["name"]: j for j in json.loads(proc.stdout)["joints"]}
    assert joints["C"]["distribution"] == "bp-cylindrical"
    assert (joints["C"]["dof"], joints["C"]["suffixes"]) == (2, ["s", "theta"])
    assert joints["C"]["transfer_rules"] is True
    assert joints["R"]["distribution"] == "baseparams"       # built-ins are still there


def test_a_mechanism_with_the_third_party_joint_loads(site, tmp_path):
    path = tmp_path / "collar.toml"
    path.write_text(MECHANISM)
    proc = cli(site, "show", str(path), "--format", "json")
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    assert info["coordinates"] == ["post_s", "post_theta", "swing"]
    assert info["joints"][0]["type"] == "C"
    assert info["dof"] == 3 and info["gruebler"] == 3 and info["loops"] == 0
    assert info["parameter_count"] == 20


def test_without_the_plugin_the_joint_type_is_unknown(tmp_path):
    """Control: the C joint comes from the installed distribution, not from baseparams."""
    path = tmp_path / "collar.toml"
    path.write_text(MECHANISM)
    proc = subprocess.run([sys.executable, "-m", "baseparams.cli", "show", str(path)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 2
    assert "joints[0].type: unknown joint type 'C'" in proc.stderr


# The same collar with masses and an exciting trajectory, for the solvers.
MOVING = MECHANISM.replace('name = "collar"\n', 'name = "collar"\ngravity = ["0", "0", "-9.81"]\n', 1) + """
[trajectory]
t_start = "0"
t_end = "10"
samples = 60
q = { post_s = "0.2*sin(0.7*t) + 0.05*sin(2.3*t)", post_theta = "1.2*sin(0.9*t + 0.4) + 0.3*sin(3.1*t)", swing = "0.8*sin(1.7*t) + 0.2*sin(4.1*t + 1)" }
"""

THIRD_PARTY_TEST = '''\
def test_collar(baseparams_validate):
    report = baseparams_validate("collar.toml")
    assert report.ok
'''

WRONG_RULE = PLUGIN.replace('return [TransferRule("quadrupole", (0, 0, 0), (0, 0, 1), 5)]',
                            'return [TransferRule("dipole", (0, 0, 0), (1, 0, 0), 4)]   # wrong on purpose')


def run_pytest(site, folder):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(site)] + [p for p in [env.get("PYTHONPATH")] if p])
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_collar.py"],
                          cwd=folder, env=env, capture_output=True, text=True, timeout=600)


def test_the_pytest_fixture_validates_the_third_party_joint(site, tmp_path):
    """A third party's test suite checks its joint and rule against the built-in solvers."""
    (tmp_path / "collar.toml").write_text(MOVING)
    (tmp_path / "test_collar.py").write_text(THIRD_PARTY_TEST)
    proc = run_pytest(site, tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 passed" in proc.stdout


@pytest.fixture(scope="module")
def wrong_site(tmp_path_factory):
    return install_distribution(tmp_path_factory.mktemp("third_party_wrong"), WRONG_RULE)


def test_a_wrong_third_party_transfer_rule_fails_the_fixture(wrong_site, tmp_path):
    (tmp_path / "collar.toml").write_text(MOVING)
    (tmp_path / "test_collar.py").write_text(THIRD_PARTY_TEST)
    proc = run_pytest(wrong_site, tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "transfer rules of C" in proc.stdout and "NOT null directions of W" in proc.stdout

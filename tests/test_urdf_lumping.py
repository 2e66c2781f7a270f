"""Fixed joints lumped before solving (issue 47, item 1): by default a URDF's fixed links
join their parents exactly, in rationals. The lumped body's ten parameters are checked
against an independent composition (4 x 4 pseudo-inertias moved by the homogeneous
transforms, J' = T J T^T, and summed: no use of the reader's parallel-axis formula), the
torques against the unlumped model's, and the rank and the notes against what they say."""

from decimal import Decimal
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy

from baseparams import registry
from baseparams.api import convert
from baseparams.dynamics.evaluator import Evaluator
from baseparams.io.loader import load_mechanism
from baseparams.numeric.backends import Float64
from baseparams.plugins.urdf.reader import read_urdf
from baseparams.plugins.urdf.rotations import rpy_matrix

DATA = Path(__file__).parent / "data" / "urdf"

# (name, mass, com xyz, inertia at the COM (ixx ixy ixz iyy iyz izz)); inertial frames unturned
LINKS = {
    "a": ("2", ("0.1", "-0.02", "0.03"), ("0.01", "0.001", "0", "0.02", "0.0005", "0.015")),
    "b": ("0.7", ("0.05", "0.01", "-0.2"), ("0.004", "0", "0.0003", "0.003", "0", "0.002")),
    "c": ("0.3", ("0", "0.04", "0.01"), ("0.0009", "-0.0001", "0", "0.0007", "0", "0.0005")),
    "d": ("1", ("0.2", "0", "0"), ("0.001", "0", "0", "0.006", "0", "0.006")),
}
# a -fixed-> b (an approximate rational rotation), b -fixed-> c (an exact pi/2), c -R-> d
FIXED = {"b": ("a", ("0.3", "-0.1", "0.25"), ("0.3", "0.2", "0.1")),
         "c": ("b", ("0", "0.2", "0"), ("0", "1.5707963267948966", "0"))}


def _urdf(tmp_path: Path) -> Path:
    links = "".join(
        f'<link name="{n}"><inertial><origin xyz="{" ".join(c)}"/><mass value="{m}"/><inertia '
        + " ".join(f'{k}="{v}"' for k, v in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), i)) + "/></inertial></link>"
        for n, (m, c, i) in LINKS.items())
    joints = ('<joint name="j1" type="revolute"><parent link="world"/><child link="a"/><origin xyz="0 0 0.1"/>'
              '<axis xyz="0 0 1"/></joint>'
              + "".join(f'<joint name="fix_{child}" type="fixed"><parent link="{parent}"/><child link="{child}"/>'
                        f'<origin xyz="{" ".join(p)}" rpy="{" ".join(r)}"/></joint>'
                        for child, (parent, p, r) in FIXED.items())
              + '<joint name="j2" type="revolute"><parent link="c"/><child link="d"/><origin xyz="0.1 0 0.05"/>'
                '<axis xyz="0 1 0"/></joint>')
    path = tmp_path / "lumped.urdf"
    path.write_text(f'<robot name="lumped"><link name="world"/>{links}{joints}</robot>', encoding="utf-8")
    return path


def _pseudo(name: str) -> sympy.Matrix:
    """The link's pseudo-inertia [[Sigma, h], [h^T, m]] about its own frame, from the file's values."""
    m, com, inertia = LINKS[name]
    m, c = sympy.Rational(m), sympy.Matrix([sympy.Rational(v) for v in com])
    ixx, ixy, ixz, iyy, iyz, izz = (sympy.Rational(v) for v in inertia)
    i_c = sympy.Matrix([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    sigma = i_c.trace() / 2 * sympy.eye(3) - i_c + m * c * c.T
    j = sympy.zeros(4, 4)
    j[:3, :3], j[:3, 3], j[3, :3], j[3, 3] = sigma, m * c, m * c.T, m
    return j


def _transform(child: str) -> sympy.Matrix:
    """The child link's frame in its parent's, as the model holds it (the rational rotation)."""
    _, p, r = FIXED[child]
    rot = sympy.Matrix(rpy_matrix(*(Decimal(v) for v in r))[0])
    t = sympy.eye(4)
    t[:3, :3], t[:3, 3] = rot, sympy.Matrix([sympy.Rational(v) for v in p])
    return t


def _parameters(j: sympy.Matrix) -> tuple[Fraction, ...]:
    sigma, h, m = j[:3, :3], j[:3, 3], j[3, 3]
    i = sigma.trace() * sympy.eye(3) - sigma
    values = (m, h[0], h[1], h[2], i[0, 0], i[0, 1], i[0, 2], i[1, 1], i[1, 2], i[2, 2])
    return tuple(Fraction(int(v.p), int(v.q)) for v in map(sympy.expand, values))


def test_lumped_body_equals_the_independent_composition(tmp_path):
    result = read_urdf(_urdf(tmp_path))
    mech = result.mechanism
    assert [b.name for b in mech.bodies] == ["a", "d"]
    assert result.merged_into == {"b": "a", "c": "a"}
    assert any("'a' lumps the fixed link(s) b, c" in note for note in result.notes)
    t_b, t_c = _transform("b"), _transform("c")
    total = _pseudo("a") + t_b * _pseudo("b") * t_b.T + (t_b * t_c) * _pseudo("c") * (t_b * t_c).T
    assert mech.bodies[0].inertia == _parameters(total)          # exact: no rounding anywhere
    assert mech.bodies[1].inertia == _parameters(_pseudo("d"))


def test_lumping_changes_no_torque_and_no_rank(tmp_path):
    path = _urdf(tmp_path)
    lumped, kept = read_urdf(path).mechanism, read_urdf(path, merge_fixed=False).mechanism
    assert len(kept.bodies) == 4 and [j.type.name for j in kept.joints].count("Fixed") == 2
    rng = np.random.default_rng(5)
    q, qd, qdd = (rng.normal(size=(2, 6)) for _ in range(3))
    taus = []
    for mech in (lumped, kept):
        k = Evaluator(mech, Float64()).sample(list(q), list(qd), list(qdd)).regressor_array()
        phi = np.array([float(v) for b in mech.bodies for v in b.inertia])
        taus.append(k @ phi)
    assert np.allclose(taus[0], taus[1], rtol=1e-12, atol=1e-13)
    exact = registry.solvers()["exact"].item
    assert exact.solve(lumped).rank == exact.solve(kept).rank


def test_loader_lumps_by_default_and_keep_fixed_opts_out(tmp_path):
    assert [b.name for b in load_mechanism(DATA / "gripper_arm.urdf").bodies] == [
        "turret_link", "upper_arm", "forearm", "finger_left_link", "finger_right_link", "camera"]
    out = tmp_path / "kept.toml"
    kept = convert(DATA / "gripper_arm.urdf", out, keep_fixed=True).mechanism
    assert "palm" in [b.name for b in kept.bodies]
    with pytest.raises(Exception, match="contradict"):
        convert(DATA / "gripper_arm.urdf", out, keep_fixed=True, merge_fixed=True)


def test_patching_a_urdf_moves_the_lumped_links_mass_to_their_body(tmp_path):
    """convert of a lumped model back to URDF: the body's link carries the lumped inertia and
    the lumped links lose theirs, so reading the written file gives the same bodies (to the
    writer's 25 digits: the rational rotation's values have no exact decimal)."""
    source = _urdf(tmp_path)
    out = tmp_path / "out.urdf"
    notes = convert(source, out).notes
    assert any("removed those of the links lumped into them: b, c" in n for n in notes)
    again = read_urdf(out).mechanism
    written = np.array([[float(v) for v in b.inertia] for b in again.bodies])
    expected = np.array([[float(v) for v in b.inertia] for b in read_urdf(source).mechanism.bodies])
    assert written.shape == expected.shape and np.allclose(written, expected, rtol=1e-20, atol=1e-22)

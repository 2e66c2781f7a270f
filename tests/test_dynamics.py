"""The regressor against closed forms, energy balance, loop closure and trajectory errors."""

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from flint import arb

from baseparams import registry
from baseparams.numeric.backends import Arb, Float64
from baseparams.dynamics.evaluator import Evaluator, Sample
from baseparams.errors import KinematicsError
from baseparams.io.loader import parse_mechanism, resolve
from baseparams.dynamics.trajectory import Trajectory, observation_matrix
from baseparams.orchestrate.model_checks import energy_balance

G0 = 9.81

PENDULUM = """
[mechanism]
name = "test_pendulum"
gravity = ["0", "0", "-9.81"]
[[bodies]]
label = 1
[[joints]]
type = "R"
parent = 0
child = 1
coordinates = ["theta"]
parent_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"], ref = ["0", "0", "1"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"], ref = ["0", "0", "1"] }
[trajectory]
q = { theta = "0.9*sin(1.3*t) + 0.3*sin(2.9*t)" }
"""

TWO_R = """
[mechanism]
name = "test_2r"
gravity = ["0", "0", "-9.81"]
[geometry]
L1 = "0.7"
[[bodies]]
label = 1
[[bodies]]
label = 2
[[joints]]
type = "R"
parent = 0
child = 1
coordinates = ["q1"]
parent_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"], ref = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"], ref = ["1", "0", "0"] }
[[joints]]
type = "R"
parent = 1
child = 2
coordinates = ["q2"]
parent_frame = { point = ["L1", "0", "0"], axis = ["0", "1", "0"], ref = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "1", "0"], ref = ["1", "0", "0"] }
"""


def test_pendulum_closed_form():
    """Axis y through the origin, gravity -z: V = g (-sin q mx + cos q mz), T = Iyy qd^2 / 2,
    so tau = Iyy qdd - g (mx cos q + mz sin q)."""
    mech = parse_mechanism(PENDULUM)
    rng = np.random.default_rng(3)
    q, qd, qdd = rng.uniform(-3, 3, 50), rng.uniform(-3, 3, 50), rng.uniform(-9, 9, 50)
    (k,) = Evaluator(mech, Float64()).sample([q], [qd], [qdd]).regressor()
    expected = {"mx1": -G0 * np.cos(q), "mz1": -G0 * np.sin(q), "Iyy1": qdd}
    for name, column in zip(mech.parameters, k):
        assert np.allclose(np.broadcast_to(column, q.shape), expected.get(name, 0 * q), atol=1e-12), name


def test_planar_2r_closed_form():
    """Two links about parallel y axes in the vertical x-z plane, by Lagrange's equations.

    Rotation about y by q maps body x to (c, 0, -s) and body z to (s, 0, c). Body 2's origin
    is at L (c1, 0, -s1). With a = qdd, d = qd, c12 = cos(q1 + q2):
      T1 = Iyy1 d1^2 / 2,  V1 = g (-s1 mx1 + c1 mz1)
      T2 = m2 L^2 d1^2 / 2 + L d1 (d1 + d2)(mx2 c2 + mz2 s2) + Iyy2 (d1 + d2)^2 / 2
      V2 = g (-m2 L s1 - mx2 s12 + mz2 c12)
    """
    mech = parse_mechanism(TWO_R)
    L = 0.7
    rng = np.random.default_rng(5)
    q1, q2, d1, d2, a1, a2 = (rng.uniform(-2, 2, 40) for _ in range(6))
    k1, k2 = Evaluator(mech, Float64()).sample([q1, q2], [d1, d2], [a1, a2]).regressor()
    c1, s1, c2, s2 = np.cos(q1), np.sin(q1), np.cos(q2), np.sin(q2)
    c12, s12 = np.cos(q1 + q2), np.sin(q1 + q2)
    zero = 0 * q1
    expect = {
        "Iyy1": (a1, zero),
        "mx1": (-G0 * c1, zero),
        "mz1": (-G0 * s1, zero),
        "m2": (L ** 2 * a1 - G0 * L * c1, zero),
        "Iyy2": (a1 + a2, a1 + a2),
        "mx2": (L * ((2 * a1 + a2) * c2 - (2 * d1 * d2 + d2 ** 2) * s2) - G0 * c12,
                L * (a1 * c2 + d1 ** 2 * s2) - G0 * c12),
        "mz2": (L * ((2 * a1 + a2) * s2 + (2 * d1 * d2 + d2 ** 2) * c2) - G0 * s12,
                L * (a1 * s2 - d1 ** 2 * c2) - G0 * s12),
    }
    for name, col1, col2 in zip(mech.parameters, k1, k2):
        e1, e2 = expect.get(name, (zero, zero))
        assert np.allclose(np.broadcast_to(col1, q1.shape), e1, atol=1e-10), name
        assert np.allclose(np.broadcast_to(col2, q1.shape), e2, atol=1e-10), name


@pytest.mark.parametrize("name", sorted(registry.mechanisms()))
def test_energy_balance(name):
    """d/dt (T + V) = zd . (K phi) for random phi; T and V come from body velocities, not from K
    (:func:`baseparams.orchestrate.model_checks.energy_balance`, the check ``validate`` runs).

    The derivative is a central difference with an exact step h = 1e-15 at 60 digits: its
    truncation error is ~h^2, far below the 1e-20 tolerance, so any error in K shows.
    """
    check = energy_balance(resolve(name))
    assert check.ok, check.detail


def test_energy_balance_catches_a_wrong_regressor(monkeypatch):
    """Control: one regressor column off by 1e-12 relative fails the check."""
    original = Sample.regressor

    def skewed(self):
        rows = original(self)
        return [[v * (1 + arb(10) ** -12) if j == 1 else v for j, v in enumerate(row)] for row in rows]

    monkeypatch.setattr(Sample, "regressor", skewed)
    check = energy_balance(resolve("planar_2r"))
    assert not check.ok, check.detail


@pytest.mark.parametrize("name", sorted(registry.mechanisms()))
def test_float64_and_arb_observation_matrices_agree(name):
    mech = resolve(name)
    trajectory = Trajectory.default(mech, samples=12)
    w64, _ = observation_matrix(mech, Float64(), trajectory)
    w_arb, _ = observation_matrix(mech, Arb(40), trajectory)
    ref = np.array([[float(w_arb[i, j].mid()) for j in range(w_arb.ncols())] for i in range(w_arb.nrows())])
    assert w64.shape == ref.shape == (12 * len(mech.independent), len(mech.parameters))
    assert np.allclose(w64, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_sla_loops_close_over_the_whole_trajectory_at_100_digits():
    mech = resolve("sla_suspension")
    _, info = observation_matrix(mech, Arb(100))
    assert info["samples"] == 200
    assert Fraction(info["closure_residual"]) <= Fraction(1, 10 ** 95)


def test_leaving_the_reachable_range_is_an_error_with_time_and_coordinates():
    mech = resolve("sla_suspension")
    trajectory = Trajectory({"theta1": 3 * sympy_sin_t(), "theta2": 0 * sympy_sin_t()},
                            tuple(Fraction(k, 10) for k in range(20)))
    with pytest.raises(KinematicsError) as info:
        observation_matrix(mech, Float64(), trajectory)
    message = str(info.value)
    assert "at t = " in message and "theta1=" in message and "theta2=" in message
    assert "residual" in message or "singular" in message
    with pytest.raises(KinematicsError) as info:
        observation_matrix(mech, Arb(30), trajectory)
    assert "at t = " in str(info.value) or "singular" in str(info.value)


def test_coordinate_limit_is_reported_with_time():
    text = PENDULUM.replace('coordinates = ["theta"]', 'coordinates = ["theta"]\nlimits = { theta = ["-0.5", "0.5"] }')
    mech = parse_mechanism(text)
    with pytest.raises(KinematicsError, match=r"at t = .* coordinate theta = .* leaves its range"):
        observation_matrix(mech, Float64())


def sympy_sin_t():
    import sympy
    return sympy.sin(sympy.Symbol("t"))


def test_exact_rational_state_gives_exact_regressor():
    """Pendulum at cos = 3/5, sin = 4/5: K is rational and equals the closed form exactly."""
    from baseparams.numeric.backends import Exact, TanHalf
    mech = parse_mechanism(PENDULUM)
    backend = Exact()
    (k,) = Evaluator(mech, backend).sample([TanHalf(Fraction(1, 2))], [backend.rational(Fraction(2))],
                                           [backend.rational(Fraction(5, 3))]).regressor()
    g = Fraction(981, 100)
    expected = [0, -g * Fraction(3, 5), 0, -g * Fraction(4, 5), 0, 0, 0, Fraction(5, 3), 0, 0]
    assert [Fraction(int(v.p), int(v.q)) for v in k] == expected


BUILTIN = {"pendulum", "planar_2r", "puma560", "scara", "four_bar", "slider_crank", "stewart_platform",
           "sla_suspension", "parallelogram_arm"}


def test_the_parametrized_tests_see_every_builtin_mechanism():
    """The tests above loop over the registry: an empty or partial one (a broken entry point)
    must fail here rather than leave them with nothing to check."""
    files = {path.stem for path in (Path(__file__).parent.parent / "mechanisms").glob("*.toml")}
    assert files == BUILTIN
    assert BUILTIN <= set(registry.mechanisms())


def test_every_builtin_file_is_registered_under_its_own_name():
    for name, registered in registry.mechanisms().items():
        assert resolve(name).name == name == registered.item.path.stem


def test_open_chain_with_a_subset_of_independent_coordinates_is_rejected():
    from baseparams.errors import InputError
    with pytest.raises(InputError, match="every tree coordinate is independent") as info:
        parse_mechanism(TWO_R + '\n[coordinates]\nindependent = ["q1"]\n', "two_r.toml")
    assert info.value.file == "two_r.toml" and info.value.key == "coordinates.independent"


def test_a_trajectory_needs_two_samples():
    from baseparams.errors import InputError
    with pytest.raises(InputError, match="from 2 to 1,000,000 are accepted"):
        Trajectory.default(parse_mechanism(PENDULUM), samples=1)


def test_coordinate_limits_hold_in_arbitrary_precision_too():
    text = PENDULUM.replace('coordinates = ["theta"]', 'coordinates = ["theta"]\nlimits = { theta = ["-0.5", "0.5"] }')
    with pytest.raises(KinematicsError, match="leaves its range"):
        observation_matrix(parse_mechanism(text), Arb(30))


def test_product_of_inertia_sign_against_a_point_mass_by_hand():
    """A point mass m at (1, 1, 0) spinning about x at rate w, held by a U joint (z, then x) at
    the origin. Newton: the centripetal force m w^2 (0, -1, 0) at r = (1, 1, 0) needs the torque
    r x F = (0, 0, -m w^2) about z. Tensor-entry convention: Ixy = -m x y = -m, so the regressor's
    tau_1 = Ixy w^2 must equal -m w^2."""
    from baseparams.model.params import from_mass_properties
    text = """
[mechanism]
name = "spinning_mass"
gravity = ["0", "0", "0"]
[[bodies]]
label = 1
[[joints]]
type = "U"
parent = 0
child = 1
coordinates = ["about_z", "about_x"]
parent_frame = { point = ["0", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }
child_frame = { point = ["0", "0", "0"], axis = ["0", "0", "1"], ref = ["1", "0", "0"] }
"""
    mech = parse_mechanism(text)
    m, w = 2.0, 3.0
    phi = [float(v) for v in from_mass_properties(Fraction(2), [Fraction(1), Fraction(1), Fraction(0)], [0] * 6)]
    assert phi[mech.parameters.index("Ixy1")] == -m
    k = Evaluator(mech, Float64()).sample([0.0, 0.0], [0.0, w], [0.0, 0.0]).regressor()
    tau_z = sum(a * b for a, b in zip(k[0], phi))
    assert tau_z == pytest.approx(-m * w ** 2)
    assert k[0][mech.parameters.index("Ixy1")] == pytest.approx(w ** 2)


def test_half_integer_powers_evaluate_in_every_backend():
    """Derivatives of sqrt in a trajectory give powers like -3/2 (float64 vs arb vs sympy)."""
    import sympy
    x = sympy.Symbol("x")
    expr = x ** sympy.Rational(-3, 2) + x ** sympy.Rational(3, 2) - x ** sympy.Rational(-1, 2)
    value = float(expr.subs(x, sympy.Rational(7, 3)))
    assert Float64().evaluate(expr, {"x": 7 / 3}) == pytest.approx(value, rel=1e-14)
    backend = Arb(40)
    with backend.activate():
        got = backend.evaluate(expr, {"x": backend.rational(Fraction(7, 3))})
        assert abs(got - arb(str(sympy.N(expr.subs(x, sympy.Rational(7, 3)), 45)))) < arb(10) ** -35


def test_singular_configuration_names_the_joints():
    """The closure Jacobian's weakest direction names the joints the loops no longer fix
    (issue 13: a singular configuration names the joint); in a batch, at the worst state."""
    mech = resolve("four_bar")
    ev = Evaluator(mech, Float64())
    names = [mech.coordinates[i] for i in ev.structure.dependent]
    joints = [mech.joint_of_coordinate(c).name for c in names]
    assert len(names) == 2
    # rows x dependent; state 0 regular, state 1 singular along the second coordinate only
    jd = [[np.array([1.0, 1.0]), np.array([0.0, 0.0])],
          [np.array([0.0, 0.0]), np.array([1.0, 1e-14])]]
    assert ev.singular_joints(jd) == f"joints at the singularity: {joints[1]} ({names[1]}); "

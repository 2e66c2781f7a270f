"""``baseparams export MECH --to python``: the written module, imported on its own, against
baseparams' own regressor, and its base regressor against the solver's base parameters."""

import ast
import importlib.util
from fractions import Fraction

import numpy as np
from click.testing import CliRunner

from baseparams.cli import main
from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.regressor import tree_regressor_array
from baseparams.dynamics.trajectory import Trajectory, samples_float64
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric.backends import Float64


def export(tmp_path, text, *extra):
    mech_file = tmp_path / "mech.toml"
    mech_file.write_text(text)
    out = tmp_path / "reg.py"
    result = CliRunner().invoke(main, ["export", str(mech_file), "--to", "python", "-o", str(out), *extra])
    assert result.exit_code == 0, result.output
    spec = importlib.util.spec_from_file_location("exported_regressor", out)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return parse_mechanism(text), module, out.read_text()


def test_exported_chain_regressor_and_base_regressor(tmp_path):
    text = generate.serial_chain(11, bodies=5, spherical=0.2)
    mech, module, source = export(tmp_path, text)
    imports = {a.name.split(".")[0] for node in ast.walk(ast.parse(source)) if isinstance(node, ast.Import)
               for a in node.names}
    assert imports == {"numpy"} and "ImportFrom" not in {type(n).__name__ for n in ast.walk(ast.parse(source))}
    n, p = len(mech.coordinates), len(mech.parameters)
    rng = np.random.default_rng(5)
    q, qd, qdd = (rng.uniform(-1.5, 1.5, (200, n)) for _ in range(3))
    K = module.regressor(q, qd, qdd)
    ev = Evaluator(mech, Float64())
    sample = ev.sample(list(q.T), list(qd.T), list(qdd.T))
    expected = tree_regressor_array(ev.kin, sample.states, sample.qdd)
    assert K.shape == (200, n, p)
    assert np.abs(K - expected).max() <= 1e-12 * max(1.0, np.abs(expected).max())
    assert np.allclose(module.regressor(q[0], qd[0], qdd[0]), K[0], rtol=0, atol=1e-12 * np.abs(K).max())
    # base regressor: its columns reproduce tau = K phi through the printed base parameters
    Kb = module.base_regressor(q, qd, qdd)
    assert Kb.shape == (200, n, module.BASE_RANK) and len(module.BASE_PARAMETERS) == module.BASE_RANK
    assert np.linalg.matrix_rank(Kb.reshape(-1, module.BASE_RANK)) == module.BASE_RANK
    phi = rng.uniform(-1, 1, p)
    index = {name: i for i, name in enumerate(module.PARAMETERS)}
    phi_b = np.array([sum(float(Fraction(c)) * phi[index[name]] for name, c in expr.items())
                      for _, expr in module.BASE_PARAMETERS])
    tau, tau_b = K @ phi, Kb @ phi_b
    assert np.abs(tau - tau_b).max() <= 1e-8 * max(1.0, np.abs(tau).max())


def test_exported_closed_loop_takes_states_on_the_manifold(tmp_path):
    text = generate.four_bar(3, samples=30)
    mech, module, source = export(tmp_path, text)
    assert "does\nnot solve the loop closure" in source or "not solve the loop closure" in source
    sample, _ = samples_float64(mech, Trajectory.default(mech, samples=30))
    q, qd, qdd = (np.stack([np.broadcast_to(v, (30,)) for v in x], axis=-1) for x in (sample.q, sample.qd, sample.qdd))
    assert np.abs(module.closure(q)[0]).max() < 1e-10
    K = module.regressor(q, qd, qdd)
    expected = sample.regressor_array()
    assert K.shape == expected.shape == (30, 1, len(mech.parameters))
    assert np.abs(K - expected).max() <= 1e-10 * max(1.0, np.abs(expected).max())
    assert module.base_regressor(q, qd, qdd).shape == (30, 1, module.BASE_RANK)


def test_export_to_stdout_and_bad_input():
    runner = CliRunner()
    result = runner.invoke(main, ["export", "pendulum", "--to", "python"])
    assert result.exit_code == 0 and "def base_regressor" in result.output
    result = runner.invoke(main, ["export", "no_such_mechanism", "--to", "python"])
    assert result.exit_code == 2
    result = runner.invoke(main, ["export", "pendulum", "--to", "fortran"])
    assert result.exit_code == 2

"""The float64 batch regressor writes each body's block into one array (issue 47): the same
bytes as stacking and concatenating the blocks (the implementation before, kept here as the
reference), and the generated code's values to rounding (an independent computation)."""

from pathlib import Path

import numpy as np
import pytest

from baseparams.dynamics import codegen
from baseparams.dynamics.regressor import _body_terms, tree_regressor_array
from baseparams.dynamics.trajectory import Trajectory, samples_float64
from baseparams.io.loader import resolve

DATA = Path(__file__).parent / "data" / "urdf"
MECHANISMS = ["puma560", "sla_suspension", "planar_2r", "stewart_platform"] + sorted(str(p) for p in DATA.glob("*.urdf"))


def _stacked(rows, size):
    return np.stack([np.stack([np.broadcast_to(v, size) for v in row], axis=-1) for row in rows], axis=-2)


def _reference(kin, states, qdd):
    """tree_regressor_array as it was: a block per body, then one concatenation."""
    size = np.broadcast_shapes(*(np.shape(v) for v in qdd))
    blocks = []
    for body in kin.mechanism.body_labels:
        jw, jv, cols = _body_terms(kin, states[body], qdd)
        coords = sorted(jw)
        if not coords:
            blocks.append(np.zeros(size + (kin.n, 10)))
            continue
        wrench = _stacked([[f[0], f[1], f[2], n[0], n[1], n[2]] for f, n in cols], size)
        jac = _stacked([jv[c] + jw[c] for c in coords], size)
        block = np.zeros(size + (kin.n, 10))
        block[..., coords, :] = np.einsum("...kr,...pr->...kp", jac, wrench)
        blocks.append(block)
    return np.concatenate(blocks, axis=-1)


@pytest.mark.parametrize("name", MECHANISMS, ids=lambda n: Path(n).stem)
def test_the_batch_regressor_is_the_stacked_one_byte_for_byte(name):
    mech = resolve(name)
    sample, _ = samples_float64(mech, Trajectory.default(mech, samples=40))
    states = sample.states
    got = tree_regressor_array(sample.kin, states, sample.qdd)
    expected = _reference(sample.kin, states, sample.qdd)
    assert got.dtype == expected.dtype and got.shape == expected.shape
    assert got.tobytes() == expected.tobytes()
    generated = codegen.tree_regressor(mech, sample.q, sample.qd, sample.qdd)
    assert np.allclose(got, generated, rtol=1e-12, atol=1e-12 * np.max(np.abs(generated)))

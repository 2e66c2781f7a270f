"""Shortcuts of identify's own work (issue 47, TIAGo's identify in <= 5 CPU s) that must not
change a result: each is checked here against the way it was computed before (kept as the
reference) and, where one exists, an independent computation."""

import numpy as np
import pytest

from baseparams.identify import impossible
from baseparams.identify.impossible import _PSD_TOLERANCE, dual, nonnegative_on_bodies, pseudo_inertia


def _one_body_at_a_time(row):
    """nonnegative_on_bodies before issue 47: body after body, stopping at the first failure."""
    row = np.asarray(row, float)
    if not np.any(row) or row.size % 10:
        return False
    scale = float(np.abs(row).max())
    for b in range(row.size // 10):
        c = row[10 * b: 10 * b + 10]
        if not np.any(c):
            continue
        if np.linalg.eigvalsh(dual(c))[0] < -_PSD_TOLERANCE * scale:
            return False
    return True


def test_the_batched_duals_are_each_dual_bit_for_bit():
    rng = np.random.default_rng(0)
    rows = rng.standard_normal((500, 10)) * rng.choice([1e-9, 1.0, 1e4], size=(500, 1))
    rows[::7, 3:] = 0
    batch = impossible._duals(rows)
    assert batch.tobytes() == np.array([dual(c) for c in rows]).tobytes()
    assert np.linalg.eigvalsh(batch).tobytes() == np.array([np.linalg.eigvalsh(dual(c)) for c in rows]).tobytes()


def test_every_body_at_once_decides_as_one_body_at_a_time():
    rng = np.random.default_rng(1)
    e = np.eye(10)
    decided = {True: 0, False: 0}
    for k in range(3000):
        bodies = rng.integers(1, 6)
        row = np.zeros(10 * bodies)
        for b in rng.choice(bodies, size=rng.integers(1, bodies + 1), replace=False):
            # mostly rows a real base map has: a body's mass, first moments, inertias, with
            # small terms of other parameters; some random ones
            part = e[rng.integers(0, 10)] * rng.choice([1.0, -1.0, 0.5]) if rng.random() < 0.7 else rng.standard_normal(10)
            part = part + (rng.random() < 0.3) * 1e-3 * rng.standard_normal(10)
            row[10 * b:10 * b + 10] = part
        if k % 500 == 0:
            row[rng.integers(0, row.size)] = np.nan
        try:
            expected = _one_body_at_a_time(row)
        except np.linalg.LinAlgError:             # a NaN reached: refused the same way
            with pytest.raises(np.linalg.LinAlgError):
                nonnegative_on_bodies(row)
            continue
        assert nonnegative_on_bodies(row) == expected, row
        decided[expected] += 1
    assert min(decided.values()) > 150              # both answers met often


def test_a_nonnegative_row_is_nonnegative_on_physical_bodies():
    """Independent: a row judged nonnegative gives row . phi >= 0 on random physical bodies
    (<D, J(phi)> with J positive semidefinite)."""
    rng = np.random.default_rng(2)
    rows = [np.eye(10)[0], np.eye(10)[4] + np.eye(10)[7], np.eye(10)[9] + 0.1 * np.eye(10)[0]]
    for row in rows:
        assert nonnegative_on_bodies(row)
        for _ in range(200):
            m = rng.uniform(0.1, 5)
            c = rng.uniform(-0.2, 0.2, 3)
            a = rng.standard_normal((3, 3))
            second = a @ a.T * 0.01 + m * np.outer(c, c)          # sum m r r^T: a physical body
            inertia = np.trace(second) * np.eye(3) - second
            phi = np.array([m, *(m * c), inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1], inertia[1, 2],
                            inertia[2, 2]])
            assert np.linalg.eigvalsh(pseudo_inertia(phi))[0] > -1e-12
            assert row @ phi >= -1e-12


@pytest.mark.parametrize("row", [np.zeros(20), np.ones(15), np.ones(11)])
def test_degenerate_rows(row):
    assert nonnegative_on_bodies(row) == _one_body_at_a_time(row)


def test_a_nan_body_is_refused_as_before():
    row = np.array([np.nan] * 10 + [0.0] * 10)
    with pytest.raises(np.linalg.LinAlgError):
        _one_body_at_a_time(row)
    with pytest.raises(np.linalg.LinAlgError):
        nonnegative_on_bodies(row)


# ----- measured_design: the pieces themselves when nothing is reduced ------------------------
@pytest.mark.parametrize("name, effects, known", [
    ("planar_2r", ["viscous_friction:q1"], []),
    ("puma560", ["viscous_friction:q1", "coulomb_friction:q2"], ["offset:q3"]),
    ("sla_suspension", [], []),
])
def test_the_design_of_unreduced_data_is_the_cut_concatenation(name, effects, known, tmp_path, monkeypatch):
    """Unreduced data (no filter, decimation or mask) take the built pieces as they are; the
    arrays (values, dtype, layout) are those cut from the concatenation that reduced data go
    through (the fast path switched off by the chunk limit)."""
    import baseparams as bp
    from baseparams.identify import fit
    from baseparams.io.loader import resolve
    from baseparams.model.mechanism import EffectSpec
    from baseparams.recordings.recording import read_data

    mech = resolve(name)
    path = tmp_path / "data.csv"
    bp.simulate(name, output=str(path), noise=0.01, samples=300)
    data, mech = read_data([str(path)], mech)
    assert not data.reduced and not data.masked
    specs = [EffectSpec(*e.split(":")) for e in effects]
    known_specs = [EffectSpec(*e.split(":")) for e in known]
    fast = fit.measured_design(mech, data, specs + known_specs, ())
    monkeypatch.setattr(fit, "CHUNK_ROWS", -1)
    cut = fit.measured_design(mech, data, specs + known_specs, ())
    for a, b in zip((fast[0].matrix, fast[1].matrix, fast[2]), (cut[0].matrix, cut[1].matrix, cut[2])):
        assert a.dtype == b.dtype and a.shape == b.shape and (a.strides == b.strides or not a.size)
        assert a.tobytes() == b.tobytes()
    assert fast[1].names == cut[1].names and len(fast[1].names) == fast[1].matrix.shape[-1]

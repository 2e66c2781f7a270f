"""diagnose --params: what the held identification already lacked on its own run is not a change.

Two simulated runs of one motion share the model errors a real robot's model has (a smooth
Coulomb law, viscous friction, a delay: none of them in the mechanism) and carry AR(1) noise.
The first run is identified with the shared effects and held (``--params``); the second is
diagnosed. What the held model lacks follows the motion in both runs: the verdict must not read
it as an unexplained change (issue 42: every real run ended "partly explained"), and must still
hold back a change the catalogue cannot name.
"""

import json

import numpy as np
import pytest

import baseparams as bp
from baseparams.diagnose.change import shared_effects
from baseparams.io.loader import resolve
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import simulate_change

SAMPLES = 1500


def _held_and_changed(tmp_path, seed: int, payload: float, extra=None):
    mechanism = resolve("puma560")
    before, after, truth = simulate_change(mechanism, samples=SAMPLES, seed=seed, payload=payload)
    if extra is not None:
        after.tau[:] = after.tau + extra(after)
    base, changed, held = tmp_path / "base.csv", tmp_path / "changed.csv", tmp_path / "base.json"
    write_measured(base, before)
    write_measured(changed, after)
    effects = [f"{e.kind}:{e.coordinate}" for e in shared_effects(mechanism)]
    held.write_text(json.dumps(bp.identify("puma560", str(base), effects=effects).to_json()))
    return bp.diagnose("puma560", str(changed), params=str(held)), truth


@pytest.mark.parametrize("seed", [1, 2])
def test_a_payload_is_the_whole_change(tmp_path, seed):
    """The payload is named on link6 (a compact load: its mass and first moments, or the whole
    body) within 3 std and the verdict is 'explained': the structure that remains is no larger
    than the held fit's own residual."""
    result, truth = _held_and_changed(tmp_path, seed, payload=0.5)
    report = result.to_json()
    names = [f"{e['kind']}:{e['coordinate']}" for e in report["effects"]]
    assert names in (["payload:link6"], ["body:link6"]), names
    mass = report["effects"][0]["coefficients"]["m"]
    assert abs(mass["value"] - truth["payload"]["mass"]) < 3 * mass["std"] + 0.05 * truth["payload"]["mass"]
    assert report["verdict"] == "explained"
    lack = report["unexplained"]["held_lack"]
    for v in lack.values():                 # within 1.5 times on one scale, and not below 1/1.5 on the other
        ratios = [v["nrms"] / v["held_nrms"], v["rms"] / v["held_rms"]]
        assert min(ratios) <= 1.5 and max(ratios) >= 1 / 1.5, v
    assert lack


def test_nothing_changed_is_nothing_missing(tmp_path):
    result, _ = _held_and_changed(tmp_path, 3, payload=0.0)
    report = result.to_json()
    assert report["effects"] == [] and report["ambiguous"] == []
    assert report["verdict"] == "nothing missing"


def test_a_change_outside_the_catalogue_still_holds_the_verdict_back(tmp_path):
    """A force on q2 that follows q2 and q3 together (no candidate has that form), 8 % of q2's
    RMS, added to the second run only: larger than the held fit's own residual, so it is
    structure that remains, not what the model always lacked."""
    def extra(data):
        force = np.zeros_like(data.tau)
        q = data.motion.q
        rms = np.sqrt(np.mean(data.tau[:, 1] ** 2))
        force[:, 1] = 0.08 * rms * np.sqrt(2) * np.sin(3 * q[:, 1] + 2 * q[:, 2])
        return force
    result, _ = _held_and_changed(tmp_path, 4, payload=0.5, extra=extra)
    report = result.to_json()
    assert report["verdict"] in ("partly explained", "unexplained")
    assert "q2" not in report["unexplained"].get("held_lack", {})


def _problem(held_nrms, held_rms):
    """What :func:`verdict._alike` reads of a diagnosis problem."""
    from types import SimpleNamespace
    return SimpleNamespace(held_nrms=np.array(held_nrms), held_rms=None if held_rms is None else np.array(held_rms))


def test_alike_between_the_force_scale_and_the_noise_scale():
    """Noise keeps its size in N m; a delay's residual grows with the force. The PUMA's q6
    after a 25 % payload (force 5.2 times): 2.1 times the held residual in N m, 0.41 times it
    in NRMS: alike. A residual larger on both scales is a change; a held run much noisier
    than this one (smaller here on both scales) is noise, not a lack: not alike."""
    from baseparams.diagnose.verdict import _alike
    problem = _problem([0.024, 0.02, 0.5, 0.02], [1.65e-6, 0.01, 0.5, 0.01])
    here_nrms = np.array([0.0098, 0.2, 0.05, 0.025])
    here_rms = np.array([3.55e-6, 0.15, 0.06, 0.012])
    assert _alike(problem, here_nrms, here_rms).tolist() == [True, False, False, True]


def test_alike_from_an_older_result_without_rms_uses_nrms_both_ways():
    from baseparams.diagnose.verdict import _alike
    problem = _problem([0.024, 0.024, 0.024], None)
    assert _alike(problem, np.array([0.0098, 0.03, 0.04]), np.array([1.0, 1.0, 1.0])).tolist() == [False, True, False]

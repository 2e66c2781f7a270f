"""The example descriptions of examples/recordings read logs written as their loggers write
them (a simulated UR5, known truth): ROS 1's ``rostopic echo -p`` CSV, UR's RTDE recorder with
currents of unknown gains and a known payload run, and a MATLAB struct. Each is read as it
is, and identify recovers the base parameters (and the gains)."""
import shutil
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from baseparams import registry
from baseparams.dynamics.trajectory import Trajectory
from baseparams.identify.base import BaseModel
from baseparams.identify.fit import identify
from baseparams.dynamics.forces import Motion, design
from baseparams.recordings.recording import read_data
from baseparams.recordings.simulate import random_physical_inertia
from baseparams.io.loader import resolve
from baseparams.numeric.backends import Float64

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "recordings"
UR5 = ROOT / "examples" / "data" / "ur5.urdf"
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]


@pytest.fixture(scope="module")
def ur5():
    mechanism = resolve(str(UR5))
    assert list(mechanism.independent) == JOINTS
    base = BaseModel.from_result(registry.solvers()["dp"].item.solve(mechanism), mechanism)
    return mechanism, base, random_physical_inertia(mechanism, np.random.default_rng(5))


def _truth(mechanism, t, phi):
    z, zd, zdd = Trajectory.default(mechanism).independent_values(mechanism, Float64(), t)
    motion = Motion(t, *(np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in a], axis=1)
                         for a in (z, zd, zdd)))
    return motion, design(mechanism, motion)[0].matrix @ phi


def _check(result, base, phi, rtol):
    truth = base.values(phi)
    error = np.abs(result.base_estimates - truth).max() / np.abs(truth).max()
    assert error < rtol, error


def _copy(name: str, folder: Path) -> Path:
    return Path(shutil.copy(EXAMPLES / name, folder / name))


def test_ros_joint_states_exported_by_rostopic(tmp_path, ur5):
    mechanism, base, phi = ur5
    rng = np.random.default_rng(1)
    t = np.cumsum(np.clip(0.002 + 1e-4 * rng.standard_normal(6000), 0.0015, 0.0025))   # 500 Hz, jittered
    motion, tau = _truth(mechanism, t, phi)
    stamps = 1_700_000_000_000_000_000 + np.round(t * 1e9).astype(np.int64)          # ns since 1970
    header = (["%time", "field.header.seq", "field.header.stamp", "field.header.frame_id"]
              + [f"field.name{k}" for k in range(6)] + [f"field.position{k}" for k in range(6)]
              + [f"field.velocity{k}" for k in range(6)] + [f"field.effort{k}" for k in range(6)])
    with open(tmp_path / "joint_states.csv", "w") as out:
        out.write(",".join(header) + "\n")
        for i in range(len(t)):
            out.write(",".join([str(stamps[i]), str(i), str(stamps[i]), ""] + JOINTS
                               + [repr(float(v)) for v in motion.q[i]] + [repr(float(v)) for v in motion.qd[i]]
                               + [repr(float(v)) for v in tau[i]]) + "\n")
    data, model = read_data([str(_copy("ros_joint_states.toml", tmp_path))], mechanism)
    _check(identify(model, data, base=base), base, phi, 3e-3)


def test_ur_rtde_currents_with_unknown_gains_and_a_payload_run(tmp_path, ur5):
    mechanism, base, phi = ur5
    t = 1234.5 + np.arange(0, 12, 0.002)                     # the controller's clock, 500 Hz
    load = np.zeros(10)                                      # 2 kg, 5 cm along the flange's axis
    load[0], load[3], load[4], load[7] = 2.0, 2.0 * 0.05, 2.0 * 0.05 ** 2, 2.0 * 0.05 ** 2
    loaded = phi.copy()
    label = next(k for k, b in enumerate(mechanism.bodies) if b.name == "wrist_3_link")
    loaded[10 * label:10 * label + 10] += load
    gains = np.array([13.0, 13.0, 9.0, 4.5, 4.5, 4.5])           # N m per A
    header = ["timestamp"] + [f"target_q_{k}" for k in range(6)] + [f"actual_q_{k}" for k in range(6)] \
        + [f"actual_current_{k}" for k in range(6)] + ["robot_mode"]
    for name, parameters in (("rtde_empty.csv", phi), ("rtde_payload.csv", loaded)):
        motion, tau = _truth(mechanism, t - t[0], parameters)
        table = np.column_stack([t, motion.q, motion.q, tau / gains, np.full(len(t), 7)])
        np.savetxt(tmp_path / name, table, delimiter=" ", header=" ".join(header), comments="", fmt="%.17g")
    data, model = read_data([str(_copy("ur_rtde.toml", tmp_path))], mechanism)
    result = identify(model, data, base=base)
    np.testing.assert_allclose([result.value(g) for g in data.gain_names], gains, rtol=3e-3)
    _check(result, base, phi, 3e-3)


def test_a_matlab_struct(tmp_path, ur5):
    mechanism, base, phi = ur5
    t = np.arange(0, 12, 0.001)
    motion, tau = _truth(mechanism, t, phi)
    scipy.io.savemat(tmp_path / "log.mat", {"log": {"t": t, "q": motion.q.T, "tau": tau, "robot": "UR5"}})
    data, model = read_data([str(_copy("matlab.toml", tmp_path))], mechanism)
    _check(identify(model, data, base=base), base, phi, 3e-3)

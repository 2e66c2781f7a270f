"""Robot arms simulated by an independent simulator (Pinocchio's RNEA) and written as a
recording (CSV and its description): a 5-harmonic motion, the URDF's damping and friction,
viscous and smooth Coulomb friction, AR(1) noise, a rigid payload. One home for
benchmarks/bench_diagnose_robots.py and the tests that replay its runs (tests/ is not a
package: put this folder on sys.path)."""

from pathlib import Path

import numpy as np

RATE, SECONDS, RHO, NOISE = 1000.0, 30.0, 0.95, 0.02       # Hz, s, AR(1) per sample, SD / RMS torque
STILL = ("finger_joint", "ripper")                           # grippers are held still


def motion(model, rng, t):
    """A 5-harmonic Fourier series per joint (0.1 Hz base) inside 60 % of its range."""
    import pinocchio as pin
    nv = model.nv
    q, qd, qdd = (np.zeros((len(t), nv)) for _ in range(3))
    names = [model.names[i] for i in range(1, model.njoints)]
    w0 = 2 * np.pi * 0.1
    for joint, name in zip(model.joints[1:], names):
        j = joint.idx_v
        if joint.nq == 1:
            lo, hi = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            lo, hi = (lo, hi) if np.isfinite(lo) and np.isfinite(hi) and hi > lo else (-np.pi, np.pi)
        else:                                                # continuous: (cos, sin)
            lo, hi = -np.pi, np.pi
        centre, span = (lo + hi) / 2, min((hi - lo) / 2, np.pi) * 0.6
        a, b = rng.standard_normal(5) / np.arange(1, 6), rng.standard_normal(5) / np.arange(1, 6)
        for k in range(1, 6):
            s, c = np.sin(k * w0 * t), np.cos(k * w0 * t)
            q[:, j] += a[k - 1] * s + b[k - 1] * c
            qd[:, j] += k * w0 * (a[k - 1] * c - b[k - 1] * s)
            qdd[:, j] -= (k * w0) ** 2 * (a[k - 1] * s + b[k - 1] * c)
        scale = 0.0 if any(word in name for word in STILL) else span / max(np.max(np.abs(q[:, j])), 1e-9)
        q[:, j] = centre + scale * q[:, j]
        qd[:, j] *= scale
        qdd[:, j] *= scale
    configuration = (lambda v: v) if model.nq == model.nv else (lambda v: pin.integrate(model, pin.neutral(model), v))
    return names, q, qd, qdd, configuration


def record(model, seed: int, folder: Path, name: str, friction: str, given: dict | None = None,
           noise_seed: int | None = None, seconds: float = SECONDS, rate: float = RATE, noise: float = NOISE) -> dict:
    """Simulate ``model`` along a motion of ``seed`` with the URDF's own damping and friction,
    the ``friction`` scenario's ('none', 'friction', 'power'; its coefficients ``given`` by
    joint name, else drawn from this run's torques) and AR(1) noise (drawn from ``noise_seed``
    when given: the same motion recorded again); write ``name``.csv and its recording
    description ``name``.toml, logged at ``rate`` Hz with noise of SD ``noise`` times each
    joint's RMS torque; return the hidden friction."""
    import pinocchio as pin
    data = model.createData()
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / rate)
    names, q, qd, qdd, configuration = motion(model, rng, t)
    tau = np.array([pin.rnea(model, data, configuration(q[i]), qd[i], qdd[i]) for i in range(len(t))])
    tau += qd * np.asarray(model.damping) + np.sign(qd) * np.asarray(model.friction)    # the URDF's own
    rms = np.sqrt(np.mean(tau ** 2, axis=0)) + 1e-3
    truth = {}
    for j in (j for j in range(model.nv) if friction != "none" and np.std(qd[:, j]) > 0):
        fv, fc, vs = 0.05 * rms[j], 0.08 * rms[j], 0.02 * np.std(qd[:, j])
        if given:
            fv, fc = given[names[j]]["fv"], given[names[j]]["fc"]
        shape = np.tanh(qd[:, j] / vs) if friction == "friction" else \
            np.sign(qd[:, j]) * (np.abs(qd[:, j]) / np.std(qd[:, j])) ** 0.4
        tau[:, j] += fv * qd[:, j] + fc * shape
        truth[names[j]] = {"fv": float(fv), "fc": float(fc)}       # unrounded: a second run given them has the same
    e = (rng if noise_seed is None else np.random.default_rng(noise_seed)).standard_normal(tau.shape)
    for i in range(1, len(e)):
        e[i] += RHO * e[i - 1]
    tau += e * noise * rms / e.std(axis=0)
    header = ["t"] + [f"q_{n}" for n in names] + [f"tau_{n}" for n in names]
    np.savetxt(folder / f"{name}.csv", np.column_stack([t, q, tau]), delimiter=",", header=",".join(header),
               comments="", fmt="%.9g")
    # a gripper held still is not logged, as on a real arm: held at its value ([held]), a mimic
    # joint (panda_finger_joint2) listed with it at the value it follows
    still = [n for n in names if any(word in n for word in STILL)]
    listed = [n for n in names if n not in still and n != "panda_finger_joint2"]
    (folder / f"{name}.toml").write_text(f'[recording]\ntime = "t"\n[[runs]]\nfile = "{name}.csv"\n[position]\n'
                                         + "".join(f'{n} = "q_{n}"\n' for n in listed) + "[torque]\n"
                                         + "".join(f'{n} = "tau_{n}"\n' for n in listed) + "[held]\n"
                                         + "".join(f"{n} = {float(q[0, names.index(n)])!r}\n" for n in still))
    return truth


def with_payload(model, mass: float | None = None) -> tuple[object, dict]:
    """A copy of ``model`` carrying a rigid payload of ``mass`` kg (default: a fifth of the
    robot's mass) on the last moving joint's body, its centre (0.05, 0.03, 0.08) m off that
    joint's frame, and the truth."""
    import pinocchio as pin
    loaded = model.copy()
    last = max(j for j in range(1, model.njoints) if not any(word in model.names[j] for word in STILL))
    if mass is None:
        mass = 0.2 * sum(model.inertias[j].mass for j in range(1, model.njoints))
    centre = np.array([0.05, 0.03, 0.08])
    loaded.inertias[last] = loaded.inertias[last] + pin.Inertia(mass, centre, np.diag([1.0, 1.0, 0.5]) * 1e-3 * mass)
    return loaded, {"joint": model.names[last], "mass": round(float(mass), 4), "centre": centre.tolist()}

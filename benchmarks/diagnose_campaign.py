"""Issue 21's campaign for ``diagnose``: data as real recordings are (coloured noise,
shapes and mismatches outside the catalogue, a payload the model lacks), with known truth.

Each scenario draws a dataset on a fixed motion (a mechanism's default trajectory, or the
TX40's recorded motion), runs :func:`baseparams.diagnose.workflow.diagnose` and scores the
answer. A "confident wrong name" is an effect under ``effects`` (named, not ambiguous, not
held back as unsupported) that is not the truth (or, for a mismatch outside the catalogue,
not in its short list of acceptable names: friction kinds on the joint whose friction has
an uncatalogued shape). Used by ``benchmarks/bench_diagnose.py --outside`` (the figures of
docs/diagnosis.md) and by ``tests/test_diagnose_real.py``, ``test_diagnose_recordings.py``
and ``test_recordings.py`` (single datasets, some replayed from their generator states).

Noise: each coordinate's SD is 2 % of its RMS inertial torque; AR(1) noise has the same
marginal SD with correlation ``rho`` from one sample to the next.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from baseparams.diagnose.problem import Problem, prepare

from baseparams.diagnose.workflow import diagnose
from baseparams.dynamics.forces import evaluate
from baseparams.recordings.simulate import random_physical_inertia, trajectory_motion
from baseparams.io.loader import resolve

NOISE = 0.02
FRICTION = {"viscous_friction", "coulomb_friction", "stribeck_friction", "position_friction", "load_friction"}


@dataclass
class Setting:
    """A mechanism and motion with its columns computed once."""
    name: str
    mechanism: object
    problem: Problem
    motion: object

    @property
    def coordinates(self):
        return self.problem.coordinates


def setting(name: str, samples: int = 1200) -> Setting:
    mechanism = resolve(name)
    motion = trajectory_motion(mechanism, samples)
    return Setting(name, mechanism, prepare(mechanism, motion, evaluate(mechanism, motion)), motion)


GENERATED = ("chain4", "tree1", "four_bar2")


def generated_setting(name: str, samples: int = 1200) -> Setting:
    """A mechanism from ``baseparams.model.generate`` (not one of the built-ins the project was
    tuned on): a 4-joint serial chain, a tree, a four-bar loop (one coordinate)."""
    from baseparams.io.loader import parse_mechanism
    from baseparams.model import generate
    text = {"chain4": lambda: generate.serial_chain(4), "tree1": lambda: generate.tree(1),
            "four_bar2": lambda: generate.four_bar(2)}[name]()
    mechanism = parse_mechanism(text)
    motion = trajectory_motion(mechanism, samples)
    return Setting(name, mechanism, prepare(mechanism, motion, evaluate(mechanism, motion)), motion)


def noise(rng, shape, sd, rho: float = 0.0) -> np.ndarray:
    white = rng.standard_normal(shape)
    if rho:
        out = np.empty_like(white)
        out[0] = white[0]
        for k in range(1, len(white)):
            out[k] = rho * out[k - 1] + np.sqrt(1 - rho ** 2) * white[k]
        white = out
    return white * sd


@dataclass
class Dataset:
    tau: np.ndarray
    truth: set                    # (kind, place) the right answer names
    acceptable: set               # names that are not wrong (truth included)
    sd: np.ndarray
    phi: np.ndarray
    extra: dict


def base(s: Setting, rng):
    phi = random_physical_inertia(s.mechanism, rng)
    clean = s.problem.inertial @ phi
    sd = NOISE * np.sqrt(np.mean(clean ** 2, axis=0))
    return phi, clean, sd


def scaled(force, sd, ratio):
    rms = np.sqrt(np.mean(force ** 2, axis=0))
    return force * ratio / np.max(rms / sd)


def on(f: int, j: int, column: np.ndarray) -> np.ndarray:
    out = np.zeros((len(column), f))
    out[:, j] = column
    return out


def driven(s: Setting, rng) -> int:
    """A coordinate that moves (random)."""
    return int(rng.integers(len(s.coordinates)))


# ----- scenarios: each returns a Dataset --------------------------------------------------------
def nothing(s, rng, rho=0.0, ratio=None):
    phi, clean, sd = base(s, rng)
    return Dataset(clean + noise(rng, clean.shape, sd, rho), set(), set(), sd, phi, {})


def catalogue(kind):
    def make(s, rng, rho=0.0, ratio=5.0):
        phi, clean, sd = base(s, rng)
        choices = [c for c in s.problem.candidates if c.kind == kind and c.coordinate in s.coordinates]
        cand = choices[int(rng.integers(len(choices)))]
        theta = rng.uniform(0.5, 1.5, size=cand.columns.shape[-1]) * (rng.choice([-1, 1]) if kind == "offset" else 1)
        if kind == "spring":
            j = s.coordinates.index(cand.coordinate)
            q = s.motion.q[:, j]
            theta[1] = theta[0] * (np.mean(q) + 0.1 * np.std(q))
        columns = cand.variants[int(rng.integers(1, len(cand.variants)))] if cand.variants else cand.columns
        force = scaled(columns @ theta, sd, ratio)
        truth = {(kind, cand.coordinate)}
        return Dataset(clean + force + noise(rng, clean.shape, sd, rho), truth, truth, sd, phi, {})
    return make


def smooth_coulomb(s, rng, rho=0.0, ratio=5.0):
    """fc tanh(qd / vs), vs a fraction of the RMS speed off the diagnosis grid."""
    phi, clean, sd = base(s, rng)
    j = driven(s, rng)
    qd = s.motion.qd[:, j]
    vs = rng.uniform(0.04, 0.2) * np.sqrt(np.mean(qd ** 2))
    force = scaled(on(clean.shape[1], j, np.tanh(qd / vs)), sd, ratio)
    truth = {("coulomb_friction", s.coordinates[j])}
    return Dataset(clean + force + noise(rng, clean.shape, sd, rho), truth, truth, sd, phi, {"vs": vs})


def delay(s, rng, rho=0.0, ratio=5.0):
    """The torques lag the positions by 0.5 to 3 samples. The delay's force is fixed by the
    delay, so the noise is scaled instead (all coordinates alike) to put the largest
    effect-to-noise ratio at ``ratio``; ``ratio`` None keeps the 2 % noise (the delay's ratio
    is then 0.7 to 3 on the PUMA: below the range the targets are set for)."""
    phi, clean, sd = base(s, rng)
    t = s.motion.t
    d = rng.uniform(0.5, 3.0) * (t[1] - t[0])
    lagged = np.stack([np.interp(t - d, t, clean[:, j]) for j in range(clean.shape[1])], axis=1)
    effect = np.sqrt(np.mean((lagged - clean) ** 2, axis=0))
    if ratio is not None:
        sd = sd * np.max(effect / sd) / ratio
    truth = {("delay", "all")}
    return Dataset(lagged + noise(rng, clean.shape, sd, rho), truth, truth, sd, phi,
                   {"d": d, "ratio": float(np.max(effect / sd))})


def small_delay(s, rng, rho=0.0, ratio=None):
    """A delay of 0.5 to 3 samples at the 2 % noise, whatever its effect-to-noise ratio."""
    return delay(s, rng, rho=rho, ratio=None)


def gear_loss(s, rng, rho=0.0, ratio=5.0):
    """mu |tau_j| sign(qd_j): friction growing with the transmitted load on one joint."""
    phi, clean, sd = base(s, rng)
    j = driven(s, rng)
    force = scaled(on(clean.shape[1], j, np.abs(clean[:, j]) * np.sign(s.motion.qd[:, j])), sd, ratio)
    truth = {("load_friction", s.coordinates[j])}
    return Dataset(clean + force + noise(rng, clean.shape, sd, rho), truth, truth, sd, phi, {})


# outside the catalogue
def power_friction(s, rng, rho=0.0, ratio=5.0):
    """sign(qd) sqrt(|qd| / rms): a friction shape the catalogue lacks (friction kinds on the
    joint are acceptable: they are the right physics, approximated)."""
    phi, clean, sd = base(s, rng)
    j = driven(s, rng)
    qd = s.motion.qd[:, j]
    force = scaled(on(clean.shape[1], j, np.sign(qd) * np.sqrt(np.abs(qd) / np.sqrt(np.mean(qd ** 2)))), sd, ratio)
    ok = {(k, s.coordinates[j]) for k in FRICTION}
    return Dataset(clean + force + noise(rng, clean.shape, sd, rho), set(), ok, sd, phi, {})


def compliance(s, rng, rho=0.0, ratio=None):
    """One joint's torque through a lightly damped second-order lag (an elastic joint's
    resonance above the motion's bandwidth): nothing in the catalogue is right."""
    phi, clean, sd = base(s, rng)
    j = driven(s, rng)
    t = s.motion.t
    dt = t[1] - t[0]
    from scipy.signal import bilinear, lfilter
    spectrum = np.abs(np.fft.rfft(clean[:, j] - clean[:, j].mean()))
    freqs = np.fft.rfftfreq(len(t), dt)
    bandwidth = freqs[np.searchsorted(np.cumsum(spectrum ** 2) / np.sum(spectrum ** 2), 0.99)]
    w = 2 * np.pi * bandwidth * rng.uniform(1.5, 3.0)
    zeta = 0.2
    b, a = bilinear([w ** 2], [1, 2 * zeta * w, w ** 2], fs=1 / dt)
    out = clean.copy()
    out[:, j] = lfilter(b, a, clean[:, j] - clean[0, j]) + clean[0, j]
    return Dataset(out + noise(rng, clean.shape, sd, rho), set(), set(), sd, phi, {})


def ripple(s, rng, rho=0.0, ratio=5.0):
    """A torque ripple periodic in time (a pump, a fan), not in any coordinate."""
    phi, clean, sd = base(s, rng)
    j = driven(s, rng)
    t = s.motion.t
    period = (t[-1] - t[0]) / rng.uniform(7, 15)
    force = scaled(on(clean.shape[1], j, np.sin(2 * np.pi * t / period + rng.uniform(0, 6.3))), sd, ratio)
    return Dataset(clean + force + noise(rng, clean.shape, sd, rho), set(), set(), sd, phi, {})


def joint_delay(s, rng, rho=0.0, ratio=None):
    """Only one joint's torque lags (3 to 6 samples). Outside the default vocabulary (one
    drive's own delay is a candidate only when named: ``--candidates delay:COORD``); that
    joint's delay or the recording's is acceptable, nothing else."""
    phi, clean, sd = base(s, rng)
    j = driven(s, rng)
    t = s.motion.t
    d = rng.uniform(3, 6) * (t[1] - t[0])
    out = clean.copy()
    out[:, j] = np.interp(t - d, t, clean[:, j])
    return Dataset(out + noise(rng, clean.shape, sd, rho), set(), {("delay", "all"), ("delay", s.coordinates[j])},
                   sd, phi, {"d": d})


# nothing hidden, the noise's level changing with the motion (as real residuals do)
def reversal_noise(s, rng, rho=0.0, ratio=None):
    """Nothing hidden; each coordinate's noise up to 4 times larger at its velocity reversals
    (1 + 3 exp(-(qd / 0.1 RMS)^2), scaled to the same RMS): a friction's unmodelled
    transition, backlash."""
    phi, clean, sd = base(s, rng)
    qd = s.motion.qd
    level = 1 + 3 * np.exp(-(qd / (0.1 * np.sqrt(np.mean(qd ** 2, axis=0)))) ** 2)
    level = level / np.sqrt(np.mean(level ** 2, axis=0))
    return Dataset(clean + noise(rng, clean.shape, sd, rho) * level, set(), set(), sd, phi, {})


def load_noise(s, rng, rho=0.0, ratio=None):
    """Nothing hidden; each coordinate's noise growing with its torque (0.2 + |tau| / RMS,
    scaled to the same RMS): a current sensor's error proportional to the current."""
    phi, clean, sd = base(s, rng)
    level = 0.2 + np.abs(clean) / np.sqrt(np.mean(clean ** 2, axis=0))
    level = level / np.sqrt(np.mean(level ** 2, axis=0))
    return Dataset(clean + noise(rng, clean.shape, sd, rho) * level, set(), set(), sd, phi, {})


UNEVEN = {"noise 4 x at reversals": reversal_noise, "noise growing with torque": load_noise}
INSIDE = {"viscous": catalogue("viscous_friction"), "coulomb": catalogue("coulomb_friction"),
          "offset": catalogue("offset"), "spring": catalogue("spring"), "rotor_inertia": catalogue("rotor_inertia")}
NEW = {"smooth_coulomb": smooth_coulomb, "delay": delay, "gear_loss": gear_loss}
BELOW = {"small_delay": small_delay}
OUTSIDE = {"power_friction": power_friction, "compliance": compliance, "ripple": ripple, "joint_delay": joint_delay}


def score(d, data: Dataset) -> str:
    """'right' (the truth named, nothing wrong), 'ambiguous' (the truth in an ambiguous group,
    nothing wrong), 'wrong' (a confident wrong name), 'unseeable' (nothing wrong named and the
    truth is a candidate the diagnosis reports it cannot see on this motion: absorbed by the
    inertial model, or nearly collinear with it), 'none' (nothing wrong named, the truth
    missed or there was no truth)."""
    named = {(e["kind"], e["coordinate"]) for e in d.effects}
    wrong = named - data.acceptable - data.truth
    if wrong:
        return "wrong"
    if data.truth and data.truth <= named:
        return "right"
    groups = [{(c["kind"], c["coordinate"]) for c in a["candidates"]} for a in d.ambiguous]
    if data.truth and all(any(t in g for g in groups) or t in named for t in data.truth):
        return "ambiguous"
    hidden = {label.split(" (")[0] for label in d.untestable if label.endswith("(absorbed)")}
    hidden |= {w["candidate"] for w in d.unexplained.get("confusable_with_model", [])}
    if data.truth and all(f"{kind}:{coordinate}" in hidden for kind, coordinate in data.truth):
        return "unseeable"
    return "none"


def run(s: Setting, make: Callable, rng, *, rho: float = 0.0, ratio: float = 5.0, **options):
    data = make(s, rng, rho=rho, ratio=ratio)
    d = diagnose(s.problem, data.tau, **options)
    return d, data, score(d, data)


# ----- a payload the model lacks, diagnosed with the model held as given -------------------------
def payload_problem(s: Setting, phi: np.ndarray) -> Problem:
    return prepare(s.mechanism, s.motion, evaluate(s.mechanism, s.motion), given=phi)


def payload(s: Setting, rng, rho=0.0, mass_fraction=None):
    """A rigid payload on the last body (mass 20-60 % of that body's, its centre 2-10 cm from
    the frame origin, a small inertia of its own); returns (tau, body name, mass, phi)."""
    phi = random_physical_inertia(s.mechanism, rng)
    k = max(i for i in range(len(s.mechanism.bodies)) if np.any(s.problem.inertial[:, :, 10 * i:10 * i + 10]))
    m = phi[10 * k] * (mass_fraction or rng.uniform(0.2, 0.6))
    c = rng.uniform(-1, 1, 3)
    c *= rng.uniform(0.02, 0.1) / np.linalg.norm(c)
    r = 0.02
    inertia_com = 0.4 * m * r ** 2
    # parameters about the body origin: m, m c, I_com + m (|c|^2 1 - c c^T)
    I = inertia_com * np.eye(3) + m * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
    extra = np.array([m, *(m * c), I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2]])
    true = phi.copy()
    true[10 * k:10 * k + 10] += extra
    clean = s.problem.inertial @ true
    sd = NOISE * np.sqrt(np.mean(clean ** 2, axis=0))
    from baseparams.diagnose.derived import body_name
    name = body_name(s.mechanism, s.mechanism.bodies[k].label)
    return clean + noise(rng, clean.shape, sd, rho), name, m, phi


# ----- through a recording as a robot writes it --------------------------------------------------
RECORDING_RATE = 1000.0             # Hz of the logs
RECORDING_MOTORS = """
[[motors]]
name = "mot1"
ratios = { q1 = "-50" }
[[motors]]
name = "mot2"
ratios = { q2 = "80" }
[[motors]]
name = "mot3"
ratios = { q2 = "30", q3 = "30" }
"""
RECORDING_RATIOS = np.array([[-50, 0, 0], [0, 80, 0], [0, 30, 30.0]])     # motor q = N q
RECORDING_GAINS = np.array([0.5, 2.0, 0.8])
RECORDING_TOML = """
[recording]
rate = {rate}
[[runs]]
files = {{ enc = "enc.csv", cur = "cur.csv" }}
[position]
mot1 = {{ column = "e1", unit = "deg" }}
mot2 = {{ column = "e2", unit = "deg" }}
mot3 = {{ column = "e3", unit = "deg" }}
[torque]
mot1 = {{ column = "i1", gain = 0.5 }}
mot2 = {{ column = "i2", gain = 2.0 }}
mot3 = {{ column = "i3", gain = 0.8 }}
"""


def motor_side_recording(folder, seed: int, hidden=(), *, delay: float = 0.0, rho: float = 0.0,
                         ratio: float = 5.0) -> list[tuple[str, str, float]]:
    """A motor-side log of a generated 3-R chain (``generate.serial_chain(seed, 3)``) with a
    coupled motor: encoders in degrees (motor q = N q), currents with gains, 10 s at 1 kHz;
    noise in the motor torques 2 % of each motor's RMS (AR(1) ``rho`` from one log sample to
    the next); each hidden (kind, coordinate, coefficient name) scaled to effect/noise
    ``ratio`` on the motor it shows most on; the torques lag ``delay`` s. Writes mech.toml,
    rec.toml, enc.csv and cur.csv in ``folder``; returns the hidden effects with their values.
    The recording is read with its defaults (low-pass and decimation: 1 kHz -> about 15 Hz)."""
    from pathlib import Path

    from baseparams.dynamics.trajectory import Trajectory
    from baseparams.dynamics.forces import Motion, design, effect_values
    from baseparams.io.loader import parse_mechanism
    from baseparams.model import generate
    from baseparams.model.mechanism import EffectSpec
    from baseparams.numeric.backends import Float64

    folder = Path(folder)
    text = generate.serial_chain(seed, bodies=3, types="R") + RECORDING_MOTORS
    mech = parse_mechanism(text)
    rng = np.random.default_rng(seed)
    phi = random_physical_inertia(mech, rng)
    t = np.arange(0, 10, 1 / RECORDING_RATE)
    z, zd, zdd = Trajectory.default(mech).independent_values(mech, Float64(), t)
    motion = Motion(t, *(np.stack([np.broadcast_to(np.asarray(v, float), t.shape) for v in a], axis=1)
                         for a in (z, zd, zdd)))
    inertial, _ = design(mech, motion)
    clean = inertial.matrix @ phi
    to_motors = np.linalg.inv(RECORDING_RATIOS.T)                # tau = N^T tau_motor
    sd = NOISE * np.sqrt(np.mean((clean @ to_motors.T) ** 2, axis=0))
    tau, values = clean.copy(), []
    for kind, coordinate, name in hidden:
        spec = EffectSpec(kind, coordinate, {name: 1.0})
        force = design(mech, motion, [spec])[1].matrix @ effect_values(mech, [spec])
        value = ratio / np.max(np.sqrt(np.mean((force @ to_motors.T) ** 2, axis=0)) / sd)
        tau = tau + value * force
        values.append((kind, coordinate, float(value)))
    if delay:
        tau = np.stack([np.interp(t - delay, t, tau[:, j]) for j in range(tau.shape[1])], axis=1)
    current = (tau @ to_motors.T + noise(rng, tau.shape, sd, rho)) / RECORDING_GAINS
    np.savetxt(folder / "enc.csv", np.degrees(motion.q @ RECORDING_RATIOS.T), delimiter=",", header="e1,e2,e3",
               comments="", fmt="%.17g")
    np.savetxt(folder / "cur.csv", current, delimiter=",", header="i1,i2,i3", comments="", fmt="%.17g")
    (folder / "mech.toml").write_text(text)
    (folder / "rec.toml").write_text(RECORDING_TOML.format(rate=RECORDING_RATE))
    return values

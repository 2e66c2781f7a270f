"""Checks of a mechanism's model itself, in ball arithmetic, independent of any solver.

- **Energy balance**: along the trajectory, d(T + V)/dt = zd . (K phi) for random phi, where
  T and V come from the bodies' velocities and positions (``Sample.energies``), not from the
  regressor K. The derivative is a central difference with an exact step h = 1e-15 at 60
  digits: its truncation error is ~h^2 = 1e-30, so any error in K above 1e-20 shows.
- **Transfer rules**: every rule a joint-type plugin claims (built in or a third party's) is
  mapped onto this mechanism's joints, and each generator n it produces must be a null
  direction of W: every ball of W n contains 0 and |W n| <= 10^-(D/2) max|W| max|n|, on
  trajectory samples and on states drawn independently of the trajectory. A wrong rule is
  caught here, not trusted.
"""

import random
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

from flint import arb, arb_mat, fmpq

from baseparams import registry
from baseparams.dynamics.evaluator import Evaluator
from baseparams.dynamics.excitation import random_batch
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.dynamics.transfers import numeric_vector, transfer_generators
from baseparams.errors import BaseparamsError
from baseparams.model.mechanism import Mechanism
from baseparams.numeric.backends import Arb

ENERGY_DIGITS = 60
ENERGY_TOLERANCE = 1e-20                      # relative, against (1 + |power|)
RULE_DIGITS = 40
RULE_SAMPLES = 12                             # trajectory samples besides the random batch
RULE_SEED = 4099


@dataclass(frozen=True)
class Check:
    name: str
    ok: bool
    detail: str
    warned: bool = False        # a known weakness the solver itself warned about (dp)
    about: str = ""             # the solver a failure is blamed on ("" for the model)

    def to_json(self) -> dict[str, Any]:
        out = {"name": self.name, "ok": self.ok, "detail": self.detail}
        if self.warned:
            out["warned"] = True
        return out


def model_checks(mechanism: Mechanism, seed: int = 1) -> list[Check]:
    """The energy balance and every joint type's transfer rules on ``mechanism``."""
    return [energy_balance(mechanism, seed=seed), *transfer_rule_checks(mechanism)]


def energy_balance(mechanism: Mechanism, points: int = 2, seed: int = 1) -> Check:
    """d(T+V)/dt against the power of the generalized forces K phi at random instants."""
    name = "energy balance"
    try:
        trajectory = Trajectory.default(mechanism)
    except BaseparamsError as exc:
        return Check(name, False, f"no trajectory to check along: {exc}")
    backend = Arb(ENERGY_DIGITS)
    rng = random.Random(f"{mechanism.name}:{seed}")
    spec = mechanism.trajectory
    assert spec is not None                  # Trajectory.default found one
    span = spec.t_end - spec.t_start
    worst = 0.0
    with backend.activate():
        ev = Evaluator(mechanism, backend)
        phi = [backend.rational(Fraction(rng.randint(-999, 999), 1000)) for _ in mechanism.parameters]
        h = backend.rational(Fraction(1, 10 ** 15))
        for _ in range(points):
            tk = spec.t_start + span * Fraction(rng.randint(1, 999), 1000)
            t = backend.rational(tk)
            try:
                _, power = _energy_and_power(ev, backend, trajectory, mechanism, t, phi)
                e_plus, _ = _energy_and_power(ev, backend, trajectory, mechanism, t + h, phi)
                e_minus, _ = _energy_and_power(ev, backend, trajectory, mechanism, t - h, phi)
            except BaseparamsError as exc:
                return Check(name, False, f"at t = {float(tk):.6g} s: {exc}")
            error = abs((e_plus - e_minus) / (2 * h) - power) / (1 + abs(power))
            worst = max(worst, float(error.upper()))      # inf if the ball is not finite
    ok = worst <= ENERGY_TOLERANCE
    return Check(name, ok, f"|d(T+V)/dt - zd.K phi| / (1 + |power|) <= {float(worst):.2g} at {points} random "
                           f"instants, random phi, {ENERGY_DIGITS} digits (tolerance {ENERGY_TOLERANCE:.0e})")


def _energy_and_power(ev: Any, backend: Any, trajectory: Any, mechanism: Mechanism, t: Any, phi: Any) -> tuple[Any, Any]:
    z, zd, zdd = trajectory.independent_values(mechanism, backend, t)
    sample = ev.sample(z, zd, zdd)
    t_form, v_form = sample.energies()
    energy = sum(a * b for a, b in zip(t_form, phi)) + sum(a * b for a, b in zip(v_form, phi))
    tau = [sum(a * b for a, b in zip(row, phi)) for row in sample.regressor()]
    return energy, sum(a * b for a, b in zip(zd, tau))


def transfer_rule_checks(mechanism: Mechanism) -> list[Check]:
    """One check per joint type present: its rules' generators are null directions of W."""
    generators, missing = transfer_generators(mechanism, registry.transfer_rules)
    by_type: dict[str, list] = {}
    for gen in generators:
        by_type.setdefault(gen.joint_type, []).append(gen)
    checks = []
    for joint in missing:
        checks.append(Check(f"transfer rules of {joint.type.name}", True,
                            f"joint type {joint.type.name} declares no transfer rules (nothing to check; "
                            f"the symbolic solver's count is then an upper bound)"))
    if not by_type:
        return _dedupe(checks)
    try:
        W, rows = _ball_observation_matrix(mechanism)
    except BaseparamsError as exc:
        return _dedupe(checks) + [Check("transfer rules", False, f"W could not be evaluated: {exc}")]
    for type_name, gens in sorted(by_type.items()):
        failures, untested, worst = [], [], 0.0
        for gen in gens:
            try:
                residual, contains = _null_residual(W, gen, mechanism)
            except ValueError as exc:
                untested.append(f"{gen.label or gen.multipole} at {gen.joint_name}: {exc}")
                continue
            worst = max(worst, residual)
            if residual > 10.0 ** (-(RULE_DIGITS // 2)) or not contains:
                failures.append(f"{gen.label or gen.multipole} at joint {gen.joint_name}: |W n| / (|W| |n|) = "
                                f"{residual:.3g}" + ("" if contains else ", W n proven nonzero"))
        joints = sorted({g.joint_name for g in gens})
        if failures:
            detail = (f"{len(failures)} of {len(gens)} generators are NOT null directions of W "
                      f"({rows} rows, {RULE_DIGITS} digits): " + "; ".join(failures[:5])
                      + (" ..." if len(failures) > 5 else ""))
        else:
            detail = (f"{len(gens) - len(untested)} generators at {len(joints)} joint(s) are null directions "
                      f"of W ({rows} rows at {RULE_DIGITS} digits; largest relative |W n| {worst:.2g})")
        if untested:
            detail += f"; {len(untested)} not evaluable in balls: " + "; ".join(untested[:3])
        checks.append(Check(f"transfer rules of {type_name}", not failures, detail))
    return _dedupe(checks)


def _dedupe(checks: list[Check]) -> list[Check]:
    seen, out = set(), []
    for c in checks:
        if c.name not in seen:
            seen.add(c.name)
            out.append(c)
    return out


def _ball_observation_matrix(mechanism: Mechanism) -> tuple[Any, int]:
    backend = Arb(RULE_DIGITS)
    trajectory = Trajectory.default(mechanism, samples=RULE_SAMPLES)
    W, _ = observation_matrix(mechanism, backend, trajectory)
    batch, _ = observation_matrix(mechanism, backend, random_batch(mechanism, trajectory, seed=RULE_SEED))
    W = backend.stack(W, batch)
    return W, W.nrows()


def _null_residual(W: Any, generator: Any, mechanism: Mechanism) -> tuple[float, bool]:
    """(max |W n| / (max|W| max|n|), every entry of W n contains 0)."""
    backend = Arb(RULE_DIGITS)
    values = numeric_vector(generator, mechanism)
    with backend.activate():
        n = arb_mat(len(values), 1)
        for i, v in enumerate(values):
            n[i, 0] = arb(fmpq(v.numerator, v.denominator)) if isinstance(v, Fraction) else backend.evaluate(v)
        res = W * n
        rows = W.nrows()
        wmax = max((abs(float(W[i, j].mid())) for i in range(rows) for j in range(W.ncols())), default=0.0) or 1.0
        nmax = max((abs(float(n[i, 0].mid())) for i in range(n.nrows())), default=0.0) or 1.0
        r = max((float(abs(res[i, 0]).upper()) for i in range(rows)), default=0.0) / (wmax * nmax)
        return r, all(res[i, 0].contains(0) for i in range(rows))

"""Weighted least squares on the base parameters and the named effects' coefficients.

The model (:mod:`baseparams.dynamics.forces`): tau = K_b phi_b + C theta (+ the known effects'
forces, subtracted first), stacked over samples and independent coordinates. Gautier's
noise weighting: an ordinary least-squares fit gives each coordinate's residual, whose
variance (over its own degrees of freedom, N minus the sum of the leverages of that
coordinate's rows) estimates the coordinate's noise SD sigma_j; each coordinate's rows are
then divided by sigma_j and refitted; the SDs are re-estimated from each weighted fit until
they settle (:mod:`.weighting`, shared with diagnosis) before the final fit. The covariance of the estimates is
s^2 (X_w^T X_w)^-1, s^2 the weighted residual variance (about 1 when the noise model holds),
computed from a QR factorisation of the column-scaled weighted matrix (no normal equations).
"""

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from baseparams import registry
from baseparams.errors import InputError
from baseparams.dynamics.evaluator import Sample
from baseparams.identify.base import BaseModel
from baseparams.recordings.data import CHUNK_ROWS, MeasuredData
from baseparams.identify.impossible import (IMPOSSIBLE_STD, Flag, advice, beyond, beyond_body_scale, beyond_scale,
                                            judge, mechanism_scales, split)
from baseparams.identify.linear import LinearFit, WeightedLinearModel
from baseparams.dynamics.forces import Design, Motion, design, effect_values, effects_design, evaluate
from baseparams.model.mechanism import EffectSpec, Mechanism
from baseparams.solvers.result import base_json

# Unit-norm columns whose pivoted-QR diagonal (the base columns) or singular value (the whole
# weighted fit) falls below this fraction of the largest are dependent to working precision:
# the data do not excite them (the SLA's weakest base
# parameter is legitimately near 1e-13, so only rounding-level dependence is refused).
NOT_EXCITED = 1e-15
# A lower bound of the unit-norm base columns' smallest singular value above this proves them
# excited without their pivoted QR (:func:`_excited`).
PROVEN_EXCITED = 1e-4
# An effect column whose distance from the span of the columns before it is below this
# fraction of its norm is absorbed (exact dependence, up to rounding).
ABSORB = 1e-9
# Above this relative distance of K from the base model's row space the fit says the base
# model is inexact (dp's coefficients on a badly conditioned mechanism).
BASE_MODEL_TOLERANCE = 1e-8
# A coordinate's noise SD is taken at least this fraction of its RMS force (noise-free data).
NOISE_FLOOR = 1e-13
# Above this condition number of the weighted regressor (unit-norm columns) a fit is said to be
# ill-conditioned, with its number: some estimates are combinations the data barely tell apart.
# Why: a wrong payload guess gave 7.45e11, a wrist gain of -1.8e-17 and exit 0 in silence.
ILL_CONDITIONED = 1e10


@dataclass
class Identification:
    """What a fit found. ``names``/``kinds``: the unknowns (base parameters "base", then the
    effects' coefficients "effect"); ``estimates``, ``covariance``; per coordinate the noise SD
    used as weight (``noise_sd``), ``nrms`` (RMS residual / RMS measured force) and the
    ``residual`` (N, f) of the weighted fit; ``condition_number`` of the weighted regressor
    with unit-norm columns."""
    mechanism: str
    data: str | None
    coordinates: tuple[str, ...]
    base: BaseModel
    effects: tuple[EffectSpec, ...]
    known: tuple[EffectSpec, ...]
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    estimates: np.ndarray
    covariance: np.ndarray
    noise_sd: np.ndarray
    nrms: np.ndarray
    residual: np.ndarray
    condition_number: float
    samples: int
    dof: int
    residual_variance: float
    notes: tuple[str, ...] = ()
    absorbed: dict = field(default_factory=dict)  # name -> {kept name: coefficient}
    base_model_error: float = 0.0
    physical: dict | None = None              # set by the caller (identify --physical)
    extras: dict = field(default_factory=dict)
    # estimates no robot has, and negative ones within their noise (.impossible.judge)
    impossible: tuple[Flag, ...] = ()
    # a bad setup said with its numbers (unknown gains at or below zero, an ill-conditioned fit)
    warnings: tuple[str, ...] = ()
    # RMS residual / the measured force's standard deviation (its mean removed): beside nrms,
    # whose RMS holds a gravity-loaded joint's mean torque (the TIAGo torso read 0.002)
    nrms_sd: np.ndarray | None = None

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0, None))

    @property
    def relative_std(self) -> np.ndarray:
        """100 std / |estimate| (%), inf for an estimate of exactly 0."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.estimates != 0, 100 * self.std / np.abs(self.estimates), np.inf)

    @property
    def base_estimates(self) -> np.ndarray:
        return self.estimates[: self.base.rank]

    @property
    def base_covariance(self) -> np.ndarray:
        return self.covariance[: self.base.rank, : self.base.rank]

    def stands_for(self, values: dict[str, float]) -> np.ndarray:
        """What the estimates estimate, given every unknown's true value (base parameters
        and all effect coefficients, absorbed ones included): each kept unknown plus its
        share of the absorbed ones. Compares a fit with a simulation's truth."""
        out = np.array([float(values[name]) for name in self.names])
        for name, into in self.absorbed.items():
            for kept, coefficient in into.items():
                out[self.names.index(kept)] += coefficient * float(values[name])
        return out

    def value(self, name: str) -> float:
        return float(self.estimates[self.names.index(name)])

    def _entry(self, k: int) -> dict:
        return {"name": self.names[k], "value": float(self.estimates[k]), "std": float(self.std[k]),
                "relative_std_percent": _finite(self.relative_std[k])}

    def to_json(self) -> dict:
        base = []
        written = base_json([{"name": n, "expression": e} for n, e in zip(self.base.names, self.base.expressions)],
                            list(self.base.coefficients)) if self.base.expressions else []
        for k, name in enumerate(self.base.names):      # every base parameter is kept (fit checks)
            json_form = {key: v for key, v in written[k].items() if key != "name"} if written else {"expression": {}}
            base.append({**self._entry(k), **json_form})
        effects = []
        for spec in self.effects:
            entries = []
            for name in registry.effects()[spec.kind].item.coefficient_names(spec.coordinate):
                entries.append(self._entry(self.names.index(name)) if name in self.names else
                               {"name": name, "value": None, "std": None, "relative_std_percent": None,
                                "absorbed_into": dict(self.absorbed[name])})
            effects.append({"kind": spec.kind, "coordinate": spec.coordinate, "coefficients": entries})
        out = {
            "mechanism": self.mechanism,
            "data": self.data,
            "solver": self.base.solver,
            "samples": self.samples,
            "coordinates": list(self.coordinates),
            "rank": self.base.rank,
            "base": base,
            "effects": effects,
            "known_effects": [{"kind": s.kind, "coordinate": s.coordinate,
                               "values": {n: str(v) for n, v in s.values.items()}} for s in self.known],
            "condition_number": _finite(self.condition_number),
            "noise_sd": dict(zip(self.coordinates, map(float, self.noise_sd))),
            "nrms": dict(zip(self.coordinates, map(float, self.nrms))),
            "nrms_sd": None if self.nrms_sd is None else {c: float(v) if math.isfinite(v) else None
                                                          for c, v in zip(self.coordinates, self.nrms_sd)},
            "dof": self.dof,
            "base_model_error": float(self.base_model_error),
            "residual_variance": float(self.residual_variance),
            "notes": list(self.notes),
        }
        gains = [self._entry(k) for k, kind in enumerate(self.kinds) if kind == "gain"]
        if gains:
            out["gains"] = gains
        # every estimate's covariance: what a later `diagnose --params` of this result allows
        # the given model to be off by (a change within it is the fit's own error)
        covariance: dict[str, Any] = {"names": list(self.names), "matrix": [
            [_finite(v) for v in row] for row in np.asarray(self.covariance, float)]}
        out["covariance"] = covariance
        impossible, near_zero = split(self.impossible)
        out["impossible"] = [f.to_json() for f in impossible]
        out["consistent_with_zero"] = [f.to_json() for f in near_zero]
        out["beyond_physical_scale"] = [f.to_json() for f in beyond(self.impossible)]
        out["warnings"] = list(self.warnings)
        out.update(self.extras)
        if self.physical is not None:
            out["physical"] = dict(self.physical)
        return out

    def to_text(self) -> str:
        lines = [f"{self.mechanism}: {self.samples} samples x {len(self.coordinates)} coordinates, "
                 f"{self.base.rank} base parameters ({self.base.solver}) + {len(self.names) - self.base.rank} "
                 f"effect coefficients; condition number {self.condition_number:.3g}"]
        width = max([len(n) for n in self.names] + [4])
        lines.append(f"  {'name':<{width}}  {'estimate':>13}  {'std':>10}  {'std %':>8}")
        for k, name in enumerate(self.names):
            if k == self.base.rank and k and self.kinds[k] == "effect":
                lines.append("  effects:")
            if self.kinds[k] == "gain" and (k == 0 or self.kinds[k - 1] != "gain"):
                lines.append("  unknown gains (torque per unit of the logged current):")
            rel = self.relative_std[k]
            lines.append(f"  {name:<{width}}  {self.estimates[k]:>13.6g}  {self.std[k]:>10.3g}  "
                         + (f"{rel:>8.3g}" if math.isfinite(rel) else f"{'-':>8}"))
        lines.append("  per coordinate: noise SD (weight) / NRMS residual (of the RMS force; of its SD)")
        of_sd = self.nrms_sd if self.nrms_sd is not None else [math.nan] * len(self.coordinates)
        for c, sd, nrms, q in zip(self.coordinates, self.noise_sd, self.nrms, of_sd):
            lines.append(f"    {c}: {sd:.4g} / {nrms:.4g}" + (f"; {q:.4g}" if math.isfinite(q) else ""))
        lines += [f"  note: {n}" for n in self.notes]
        lines += impossible_lines(self.impossible, "  ")
        return "\n".join(lines)


def impossible_lines(flags: Sequence[Flag], indent: str = "") -> list[str]:
    """The estimates no robot has, then the negative ones within their noise, as text."""
    impossible, near_zero = split(flags)
    lines = []
    if impossible:
        lines.append(f"{indent}IMPOSSIBLE estimates (no robot has these; more than {IMPOSSIBLE_STD:g} std below 0):")
        lines += [f"{indent}  {f.text()}" for f in impossible]
        lines += [f"{indent}  what to do: {text}" for text in advice(impossible)]
    if near_zero:
        lines.append(f"{indent}negative but consistent with zero (within {IMPOSSIBLE_STD:g} std of 0):")
        lines += [f"{indent}  {f.text()}" for f in near_zero]
    far = beyond(flags)
    if far:
        lines.append(f"{indent}BEYOND ANY PHYSICAL SCALE (not estimates of what they stand for):")
        lines += [f"{indent}  {f.text()}" for f in far]
    return lines


def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def split_effects(mechanism: Mechanism, named: Sequence[EffectSpec]) -> tuple[list[EffectSpec], list[EffectSpec]]:
    """(to identify, known): the mechanism's [[effects]] with every coefficient given are
    known (their force is subtracted), the others are identified, and so is every effect in
    ``named`` (which overrides a known one of the same kind and coordinate)."""
    named_keys = {(s.kind, s.coordinate) for s in named}
    identify: list[EffectSpec] = []
    known: list[EffectSpec] = []
    for spec in mechanism.effects:
        if (spec.kind, spec.coordinate) in named_keys:
            continue
        coefficients = registry.effects()[spec.kind].item.coefficients
        (known if all(c in spec.values for c in coefficients) else identify).append(spec)
    seen = set()
    for spec in list(identify) + list(named):
        key = (spec.kind, spec.coordinate)
        if key in seen:
            raise InputError(f"the effect {spec.kind} on {spec.coordinate} is named twice", key="effect")
        seen.add(key)
    return identify + [EffectSpec(s.kind, s.coordinate) for s in named], known


def identify(mechanism: Mechanism, data: MeasuredData, *, effects: Sequence[EffectSpec] = (),
             base: BaseModel, known: Sequence[EffectSpec] = ()) -> Identification:
    """Fit the base parameters and ``effects``' coefficients to ``data`` (``known`` effects,
    every coefficient given, are subtracted first). An effect coefficient whose column is a
    combination of the columns before it (a zero-free-length strut spring on the SLA acts
    exactly like gravity) cannot be identified: it is absorbed, like a grouped inertial
    parameter, and ``absorbed`` says what the remaining estimates then stand for."""
    effects, known = tuple(effects), tuple(known)
    n, f = data.tau.shape
    identified_width = sum(len(registry.effects()[s.kind].item.coefficients) for s in effects)
    inertial, columns, payload = measured_design(mechanism, data, effects + known)
    y = data.tau - payload
    if known:
        y = y - columns.matrix[:, :, identified_width:] @ effect_values(mechanism, known)
    Kb = base.columns(inertial.matrix)
    # base columns only: K_b itself (a copy is 24 MB of fresh pages on TIAGo)
    X = np.concatenate([Kb, columns.matrix[:, :, :identified_width]], axis=-1) if identified_width else Kb
    all_names = tuple(base.names) + tuple(columns.names[:identified_width])
    if data.gain_names:               # unknown current gains: model - sum(g c) = known forces
        if not np.any(y):
            raise InputError(f"every torque channel's gain is unknown ({', '.join(data.gain_names)}) and no "
                             "force is known: add a run with a known payload ([runs.payload]) or give "
                             "one gain", file=data.path)
        assert data.gain_columns is not None
        X = np.concatenate([X, -data.gain_columns], axis=-1)
        all_names += tuple(data.gain_names)
    notes = list(data.notes)
    outside = base.residual_outside(inertial.matrix, Kb)
    if outside > BASE_MODEL_TOLERANCE:
        notes.append(f"the {base.solver} solver's base parameters reproduce the regressor only to "
                     f"{outside:.2g} (relative): its coefficients carry too few digits for this "
                     "mechanism; a certified solver (--solver vp) models it exactly")
    stacked = X.reshape(n * f, -1)
    scale = np.linalg.norm(stacked, axis=0)
    dead = [all_names[k] for k in range(len(all_names)) if scale[k] == 0]
    if dead:
        raise InputError(f"{', '.join(dead)} have no effect on these data (their columns are zero): "
                         "drop them or excite them", file=data.path)
    if n * f <= len(all_names):
        raise InputError(f"{n} samples x {f} coordinates = {n * f} equations for {len(all_names)} unknowns "
                         f"({base.rank} base parameters, {identified_width} effect coefficients): "
                         "more samples are needed", file=data.path)
    # base columns only: their excitation check can wait for the fit, whose singular values
    # usually prove it (:func:`_excited`); the pivoted QR then is not needed
    deferred = len(all_names) == base.rank
    kept, absorbed = (list(range(base.rank)), {}) if deferred else _independent(stacked / scale, base.rank,
                                                                                all_names, data.path)
    absorbed = {name: {k: v * scale[all_names.index(name)] / scale[all_names.index(k)]
                       for k, v in into.items()} for name, into in absorbed.items()}
    for name, into in absorbed.items():
        effects_part = [f"{k} + {v:.4g} {name}" for k, v in into.items() if k not in base.names]
        grouped = [k for k in into if k in base.names]
        parts = effects_part + ([f"{len(grouped)} base parameters ({', '.join(grouped[:3])}"
                                 + (", ..." if len(grouped) > 3 else "") + ")"] if grouped else [])
        notes.append(f"{name} cannot be identified on these data (its column is a combination of the "
                     f"others): it is absorbed into {'; '.join(parts)} (JSON: absorbed_into)")
    stacked, scale = stacked[:, kept], scale[kept]
    names = tuple(all_names[k] for k in kept)
    kinds = tuple("base" if k < base.rank else "gain" if all_names[k] in data.gain_names else "effect"
                  for k in kept)
    p = len(kept)
    rms_force = np.sqrt(np.mean(y ** 2, axis=0))
    floor = NOISE_FLOOR * max(float(rms_force.max()), np.finfo(float).tiny)
    fit = WeightedLinearModel(stacked.reshape(n, f, p), y).fit(
        floor=floor, rank_tol=NOT_EXCITED, cov_type="hac" if data.reduced else "nonrobust")
    if deferred and not _excited(fit):
        _independent(stacked / scale, base.rank, all_names, data.path)    # raises when a column is not excited
    if fit.rank < p:
        null = fit.null_direction()
        involved = [names[k] for k in np.argsort(-np.abs(null)) if abs(null[k]) > 0.1 * np.abs(null).max()]
        raise InputError(f"{', '.join(involved)} cannot be told apart on these data (their columns are "
                         "collinear): drop one of the effects, or excite the mechanism differently",
                         file=data.path)
    # filtered rows are correlated (the low-pass passes the noise's band only): the classical
    # s^2 (A^T A)^-1 understated the spread 1.3-10x on simulated recordings, hence HAC
    estimates, covariance, sigma = fit.coefficients, fit.covariance, 1.0 / fit.weights
    variance, condition = fit.scale_variance, fit.condition_number
    final = y - (stacked @ estimates).reshape(n, f)
    forces = measured_forces(data, names, estimates)
    measured_rms, measured_sd = np.sqrt(np.mean(forces ** 2, axis=0)), np.std(forces, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        nrms = np.where(measured_rms > 0, np.sqrt(np.mean(final ** 2, axis=0)) / measured_rms, 0.0)
        nrms_sd = np.where(measured_sd > 0, np.sqrt(np.mean(final ** 2, axis=0)) / measured_sd, np.inf)
    coefficients = {name: (spec.kind, c) for spec in effects for c, name in zip(
        registry.effects()[spec.kind].item.coefficients,
        registry.effects()[spec.kind].item.coefficient_names(spec.coordinate))}
    flags = judge(parameters=base.parameters, base_map=base.B, names=names, values=estimates,
                  std=np.sqrt(np.clip(np.diag(covariance), 0, None)), covariance=covariance, effects=coefficients,
                  absorbed=absorbed, bodies={b.label: b.name for b in mechanism.bodies})
    flags += beyond_scale(names, estimates, np.sqrt(np.clip(np.diag(covariance), 0, None)), coefficients)
    flags += beyond_body_scale(base.names, base.B, names, estimates, np.sqrt(np.clip(np.diag(covariance), 0, None)),
                               mechanism_scales(mechanism, base.parameters))
    return Identification(mechanism=mechanism.name, data=data.path, coordinates=data.coordinates,
                          base=base, effects=effects, known=known, names=names, kinds=kinds,
                          estimates=estimates, covariance=covariance, noise_sd=sigma, nrms=nrms,
                          residual=final, condition_number=condition, samples=n, dof=n * f - p,
                          residual_variance=variance, notes=tuple(notes), absorbed=absorbed,
                          base_model_error=outside, impossible=tuple(flags),
                          warnings=tuple(setup_warnings(names, kinds, estimates, covariance, condition)),
                          nrms_sd=nrms_sd)


def setup_warnings(names: Sequence[str], kinds: Sequence[str], estimates: np.ndarray, covariance: np.ndarray,
                   condition: float) -> list[str]:
    """What says a bad setup, with its numbers: an unknown current gain that is zero within
    IMPOSSIBLE_STD of its std, or negative (a torque constant is positive: the logged current's
    sign is the other way, or the model misses the force the gain was to scale), and a
    condition number above ILL_CONDITIONED. Why: a wrist gain of -1.8e-17 with a condition
    number of 7.45e11 was exit 0 without a word (issue 44)."""
    std = np.sqrt(np.clip(np.diag(covariance), 0, None))
    out = []
    for k, (name, kind) in enumerate(zip(names, kinds)):
        if kind != "gain":
            continue
        value = float(estimates[k])
        if abs(value) <= IMPOSSIBLE_STD * std[k]:
            out.append(f"{name} = {value:.3g} +- {std[k]:.2g}: zero within its noise, so the data do not determine "
                       "this current's gain (nothing known fixes its scale on this coordinate: a known payload that "
                       "moves it, or a known gain; a wrong payload guess gives this too)")
        elif value < 0:
            out.append(f"{name} = {value:.3g} +- {std[k]:.2g}: a negative gain (a torque constant is positive): the "
                       "current is logged with the other sign (scale = -1 on the channel), or the model misses the "
                       "force it was to scale")
    if math.isfinite(condition) and condition > ILL_CONDITIONED:
        weakest = [names[k] for k in np.argsort(-np.where(np.abs(estimates) > 0, std / np.maximum(np.abs(estimates),
                                                                                                 np.finfo(float).tiny),
                                                          np.inf))[:3]]
        out.append(f"the fit is ill-conditioned: condition number {condition:.3g} (above {ILL_CONDITIONED:.0e}); the "
                   f"data barely tell some estimates apart (largest relative std: {', '.join(weakest)}): excite the "
                   "motion more richly, or check the description (payload, gains, held joints)")
    elif not math.isfinite(condition):
        out.append("the fit is singular (condition number infinite): some estimates are not determined")
    return out


def unfiltered(result: "Identification", mechanism: Mechanism, data: MeasuredData, on_band: "Prediction"
               ) -> "Prediction":
    """The model's forces against the forces as measured, without the parallel filter, at the
    fit's rows (``on_band``: the prediction on the filtered rows, returned when nothing was
    filtered). Why: an NRMS on filtered torques cannot be compared with another tool's unless
    its filter is matched (issue 44); this one can."""
    if not data.reduced:
        return on_band
    return predict(result, mechanism, data.unreduced())


def measured_design(mechanism: Mechanism, data: MeasuredData, effects: Sequence[EffectSpec],
                    known: Sequence[EffectSpec] = ()) -> tuple[Design, Design, np.ndarray]:
    """(inertial, effects, the known payloads' forces and ``known`` effects' (every value
    given) at the model rows, reduced) at the fit's rows: the model's columns
    at the model rows, then filtered and decimated like the torques (parallel filtering), so
    the model and the measurement see the same filter; chunk by chunk on long data
    (:meth:`MeasuredData.reduced_columns`: a Panda logged 120 s at 1 kHz has 0.8 GB of
    columns). The one home of the model's columns on measured data (identify, predict,
    diagnose)."""
    p = len(mechanism.parameters)
    names: list[str] = []

    def pieces(motion: Motion, sample: Sample | None, run: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        sample = sample if sample is not None else evaluate(mechanism, motion)
        inertial, columns = design(mechanism, motion, effects, sample)
        names[:] = columns.names
        force = effects_design(mechanism, sample, motion.count, known).matrix @ effect_values(mechanism, known) \
            if known else np.zeros(inertial.matrix.shape[:2])
        payload = data.payload_of_run(run)
        if payload is not None:
            force = force + inertial.matrix[:, :, :len(payload)] @ payload
        return inertial.matrix, columns.matrix, force

    def build(motion: Motion, sample: Sample | None, run: int) -> np.ndarray:
        inertial, columns, force = pieces(motion, sample, run)
        return np.concatenate([inertial, columns, force[:, :, None]], axis=-1)

    if (not data.reduced and not data.masked and data.motion.count <= CHUNK_ROWS
            and len({s.run for s in data.segments}) == 1):
        # nothing to filter, decimate or mask (reduced_columns would return the whole of one
        # build): the pieces themselves, not cut from their concatenation (TIAGo: 37 MB twice)
        parts = pieces(data.motion, data.sample, data.segments[0].run)
    else:
        full = data.reduced_columns(build)
        parts = (full[:, :, :p], full[:, :, p:-1], full[:, :, -1])
    inertial, columns, payload = (np.ascontiguousarray(a) for a in parts)
    return Design(tuple(mechanism.parameters), inertial), Design(tuple(names), columns), payload


def measured_forces(data: MeasuredData, names: Sequence[str], estimates: np.ndarray) -> np.ndarray:
    """The data's generalized forces (n, f), its unknown current gains taken as estimated
    (every one must be among ``names``)."""
    if not data.gain_names:
        return data.tau
    missing = [g for g in data.gain_names if g not in names]
    if missing:
        raise InputError(f"the gains {', '.join(missing)} are unknown in these data and were not identified",
                         file=data.path)
    gains = np.array([estimates[list(names).index(g)] for g in data.gain_names])
    return data.tau + data.gain_columns @ gains


@dataclass
class Prediction:
    """The identified model's forces on measured data it may not have seen: per coordinate the
    RMS error and the NRMS (RMS error / RMS measured force), and the traces."""
    data: str | None
    coordinates: tuple[str, ...]
    t: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    rows: np.ndarray | None = None     # (n, f) bool: the forces measured (a run's channel left out: False)
    # the NRMS against the forces as measured, without the parallel filter (:func:`unfiltered`)
    nrms_unfiltered: np.ndarray | None = None

    def _mean(self, x: np.ndarray) -> np.ndarray:
        """Per coordinate, the mean of ``x`` (n, f) over its measured rows (0 where none)."""
        if self.rows is None:
            return np.mean(x, axis=0)
        count = self.rows.sum(axis=0)
        return np.where(count > 0, (x * self.rows).sum(axis=0) / np.maximum(count, 1), 0.0)

    @property
    def unmeasured(self) -> tuple[str, ...]:
        """The coordinates without a measured force in these data (every channel left out)."""
        if self.rows is None:
            return ()
        measured = np.asarray(self.rows.any(axis=0), dtype=bool)
        return tuple(c for c, any_row in zip(self.coordinates, measured) if not any_row)

    @property
    def undefined(self) -> tuple[str, ...]:
        """The coordinates whose NRMS is undefined: measured, and their force 0 in every sample
        (a dead channel). Their ``nrms`` reads 0 and means nothing: JSON null, text "undefined".
        Why (issue 46): a run with every torque 0 was predicted with "nrms": 0.0, a perfect score."""
        size = self._mean(self.measured ** 2)
        return tuple(c for c, s in zip(self.coordinates, size) if s == 0 and c not in self.unmeasured)

    @property
    def rms(self) -> np.ndarray:
        return np.sqrt(self._mean((self.measured - self.predicted) ** 2))

    @property
    def nrms(self) -> np.ndarray:
        size = np.sqrt(self._mean(self.measured ** 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(size > 0, self.rms / size, 0.0)

    @property
    def nrms_sd(self) -> np.ndarray:
        """RMS error / the measured force's standard deviation (its mean over the measured rows
        removed): a gravity-loaded joint's mean torque does not make it look better."""
        mean = self._mean(self.measured)
        sd = np.sqrt(self._mean((self.measured - mean) ** 2))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(sd > 0, self.rms / sd, np.inf)

    @property
    def overall_rms(self) -> float:
        error = (self.measured - self.predicted) ** 2
        if self.rows is not None and self.rows.any():
            return float(np.sqrt(error[self.rows].mean()))
        return float(np.sqrt(np.mean(error)))

    def to_json(self) -> dict:
        undefined = self.undefined

        def ratios(values: np.ndarray) -> dict[str, float | None]:
            return {c: None if c in undefined else float(v) for c, v in zip(self.coordinates, values)}
        return {"data": self.data, "samples": int(len(self.t)),
                "rms": dict(zip(self.coordinates, map(float, self.rms))),
                "nrms": ratios(self.nrms),
                "nrms_sd": {c: v if v is not None and math.isfinite(v) else None for c, v in ratios(self.nrms_sd).items()},
                "rms_overall": self.overall_rms} | ({"unmeasured": list(self.unmeasured)} if self.unmeasured else {}) \
            | ({"nrms_undefined": list(undefined)} if undefined else {}) \
            | ({"nrms_unfiltered": ratios(self.nrms_unfiltered)} if self.nrms_unfiltered is not None else {})

    def to_text(self) -> str:
        lines = [f"  prediction on {self.data} ({len(self.t)} samples): RMS error overall {self.overall_rms:.4g}"]
        raw = self.nrms_unfiltered if self.nrms_unfiltered is not None else [None] * len(self.coordinates)
        lines += [f"    {c}: not measured (its torque channel left out)" if c in self.unmeasured else
                  f"    {c}: RMS {r:.4g} / NRMS undefined (the measured force is 0 in every sample: a dead "
                  "channel?)" if c in self.undefined else
                  f"    {c}: RMS {r:.4g} / NRMS {q:.4g}" + (f" (unfiltered {u:.4g})" if u is not None else "")
                  + (f", of the SD {d:.4g}" if np.isfinite(d) else "")
                  for c, r, q, u, d in zip(self.coordinates, self.rms, self.nrms, raw, self.nrms_sd)]
        return "\n".join(lines)


def predict(result: Identification, mechanism: Mechanism, data: MeasuredData) -> Prediction:
    """The forces ``result`` predicts on ``data`` (identified and known effects, the data's
    known payloads included), beside the measured ones."""
    effects = tuple(result.effects) + tuple(result.known)
    identified_width = sum(len(registry.effects()[s.kind].item.coefficients) for s in result.effects)
    inertial, columns, payload = measured_design(mechanism, data, effects)
    X = np.concatenate([result.base.columns(inertial.matrix), columns.matrix[:, :, :identified_width]], axis=-1)
    names = tuple(result.base.names) + tuple(columns.names[:identified_width])
    model = [k for k, name in enumerate(result.names) if name in names]     # not the current gains
    predicted = X[:, :, [names.index(result.names[k]) for k in model]] @ result.estimates[model]
    if result.known:
        predicted = predicted + columns.matrix[:, :, identified_width:] @ effect_values(mechanism, result.known)
    predicted = predicted + payload
    return Prediction(data.path, data.coordinates, data.t, measured_forces(data, result.names, result.estimates),
                      predicted, data.measured() if data.masked else None)


def fitted(result: Identification, data: MeasuredData) -> Prediction:
    """:func:`predict` on the data ``result`` was fitted to, from its residual (measured less
    predicted, the same forces to rounding) instead of the model's columns made again. Why:
    on long recordings the columns are most of the work (a Panda logged 120 s at 1 kHz: 3.2 of
    `identify`'s 12 CPU s)."""
    measured = measured_forces(data, result.names, result.estimates)
    return Prediction(data.path, data.coordinates, data.t, measured, measured - result.residual,
                      data.measured() if data.masked else None)


def _excited(fit: LinearFit) -> bool:
    """Do the weighted fit's singular values prove that the pivoted QR of the unweighted
    unit-norm columns (:func:`_independent`) finds every base column excited? With A those
    columns and X = W A E the fit's (W the rows' weights, E the diagonal rescaling each weighted
    column to unit norm, no entry above 1 / min W), s_min(A) >= s_min(X) min W / max W; and each diagonal
    entry of a pivoted QR of A is a column's distance from the span of others, at least
    s_min(A), against a first entry of 1. Proven when that bound exceeds PROVEN_EXCITED, far
    above NOT_EXCITED and the rounding of either factorisation. Why: that QR of the 9,600 x
    310 base columns was 0.2 CPU s of TIAGo's identify (issue 47), beside the fit's own."""
    s, w = fit.singular_values, fit.weights
    if fit.rank < len(fit.coefficients) or not s.size or not np.all(np.isfinite(w)) or not np.min(w) > 0:
        return False
    return bool(s[-1] * np.min(w) / np.max(w) > PROVEN_EXCITED)


def _independent(matrix: np.ndarray, rank: int, names: tuple[str, ...], path: str | None
                 ) -> tuple[list[int], dict[str, dict[str, float]]]:
    """(kept columns, absorbed): the base columns (all must be excited), then each effect
    column kept unless it lies in the span of the kept ones (relative residual below ABSORB),
    in which case its expansion over them {kept name: coefficient} is returned."""
    basis = np.zeros((len(matrix), 0))
    if rank:
        # Q only when effect columns are to be tested against it: forming it was 0.1 s of
        # TIAGo's identify (9,600 x 310, issue 47); R and the pivots are the same either way
        if matrix.shape[1] > rank:
            basis, r_factor, pivots = scipy.linalg.qr(matrix[:, :rank], mode="economic", pivoting=True)
        else:
            r_factor, pivots = scipy.linalg.qr(matrix[:, :rank], mode="r", pivoting=True)
        diagonal = np.abs(np.diag(r_factor))
        weak = [names[pivots[k]] for k in range(rank) if diagonal[k] <= NOT_EXCITED * diagonal[0]]
        if weak:
            raise InputError(f"these data do not excite the base parameters {', '.join(weak)} (the columns "
                             "are dependent on this trajectory): excite the mechanism more richly",
                             file=path)
    kept = list(range(rank))
    absorbed = {}
    for k in range(rank, matrix.shape[1]):
        column = matrix[:, k]
        rest = column - basis @ (basis.T @ column)
        rest = rest - basis @ (basis.T @ rest)            # twice is enough (Kahan, Parlett)
        size = np.linalg.norm(rest)
        if size <= ABSORB * np.linalg.norm(column):
            coefficients = scipy.linalg.lstsq(matrix[:, kept], column)[0]
            absorbed[names[k]] = {names[i]: float(c) for i, c in zip(kept, coefficients)
                                  if abs(c) > 1e-6 * np.abs(coefficients).max()}
            continue
        basis = np.column_stack([basis, rest / size])
        kept.append(k)
    return kept, absorbed

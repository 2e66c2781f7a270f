"""Measured data: simulate it, identify a model from it, diagnose what the model misses.

The statistics live in :mod:`baseparams.identify`; these functions read the inputs (names,
files, effect texts), run the steps in order and return the results the command line
prints. scipy, statsmodels and cvxpy are imported when a function runs.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from fractions import Fraction
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

from baseparams.errors import InputError

from .solving import DEFAULT_SOLVER, MechanismLike, Progress, get_solver, load, check_solver_options, run_solver

if TYPE_CHECKING:
    from baseparams.recordings.data import MeasuredData
    from baseparams.model.mechanism import EffectSpec, Mechanism
    from baseparams.diagnose.given import Given

    from .results import ChangeDiagnosed, Diagnosed, Fit, Simulation

PathText = Union[str, "PathLike[str]"]
DataPaths = Union[PathText, Sequence[PathText]]
EffectLike = Union[str, "EffectSpec"]


def _paths(data: DataPaths) -> list[str]:
    return [str(data)] if isinstance(data, (str, PathLike)) else [str(p) for p in data]


def _validation(path: str, loaded: Any, fitted: Any, fit_filter: dict | None = None) -> Any:
    """A ``--validate`` recording's data. One that holds joints (``[held]``, as the fit's
    description does) is read against the mechanism as loaded, where its names and patterns
    refer, and must hold the same ones; any other against the fitted (held) mechanism. Why:
    read against the held mechanism, the fit's own description failed: its held joints were
    no longer coordinates ("the pattern '*' matches no coordinate without a channel")."""
    from baseparams.recordings.recording import holds, read_data
    if not holds(path):
        return read_data([path], fitted, fit_filter=fit_filter)[0]
    measured, model = read_data([path], loaded, fit_filter=fit_filter)
    if model.coordinates != fitted.coordinates:
        raise InputError("holds other coordinates than the fitted data's description ("
                         f"{', '.join(c for c in loaded.coordinates if c not in model.coordinates) or 'none'} "
                         f"against {', '.join(c for c in loaded.coordinates if c not in fitted.coordinates) or 'none'})",
                         file=path, key="held")
    return measured


ResultLike = Union[PathText, Mapping[str, Any], Any]
"""A result file's path, or the result itself: an object with ``to_json()`` (``bp.identify``'s
:class:`~.results.Fit`, an :class:`~baseparams.identify.fit.Identification`) or its JSON dict."""


def result_json(value: Any) -> dict | None:
    """The JSON of a result given as an object (``to_json()``) or a dict; None for a path."""
    if hasattr(value, "to_json") and callable(value.to_json):
        return dict(value.to_json())
    if isinstance(value, Mapping):
        return dict(value)
    return None


def _check_result(value: Any, key: str = "params") -> None:
    """A result argument is a path, a result object or its JSON dict (else exit 2, not a
    repr taken for a file name)."""
    if value is not None and result_json(value) is None and not isinstance(value, (str, PathLike)):
        raise InputError(f"expected a result file's path or a result object (bp.identify's), not "
                         f"{type(value).__name__}", key=key)


@contextmanager
def result_file(value: ResultLike | None, name: str = "result.json") -> Iterator[str | None]:
    """A path wherever the command line takes a result file: the path given, or the result
    object's JSON written to a temporary file for the duration. Why: ``bp.diagnose(params=fit)``
    with an identify result object failed with a 67 000-character error (its repr taken for a
    path); the API takes a result wherever the CLI takes a result file (issue 44)."""
    if value is None:
        yield None
        return
    data = result_json(value)
    if data is None:
        if not isinstance(value, (str, PathLike)):
            raise InputError(f"expected a result file's path or a result object (bp.identify's), not "
                             f"{type(value).__name__}", key="params")
        yield str(value)
        return
    with tempfile.TemporaryDirectory(prefix="baseparams-result-") as folder:
        path = Path(folder) / name
        path.write_text(json.dumps(data), encoding="utf-8")
        yield str(path)


def _say(progress: Progress | None, message: str) -> None:
    if progress is not None:
        progress(message)


def same_file(a: PathText | None, b: PathText | None) -> bool:
    """Whether two paths name the same file (both given)."""
    return bool(a and b) and Path(a).resolve() == Path(b).resolve()      # type: ignore[arg-type]


# ----- simulate --------------------------------------------------------------------------
def simulate(mech: MechanismLike, *, output: PathText | None = None, effects: Sequence[EffectLike] = (),
             noise: float | Sequence[float] | str = 0.0, seed: int = 0, samples: int | None = None,
             truth: PathText | None = None, random_inertia: bool = False, derivatives: bool = True,
             progress: Progress | None = None) -> "Simulation":
    """Synthetic measured data along ``mech``'s exciting trajectory: tau = K phi + hidden
    ``effects`` (``"viscous_friction:q1=0.5"`` or EffectSpec with values) + Gaussian ``noise``
    (one SD or one per coordinate). Writes the CSV to ``output`` and the truth (JSON) to
    ``truth`` when given; the result holds both (``.data``, ``.truth``, ``.to_frame()``)."""
    from baseparams.recordings.data import MIN_SAMPLES, write_measured
    from baseparams.identify.fit import split_effects
    from baseparams.recordings.simulate import simulate as run_simulation
    from baseparams.io.atomic import atomic_write

    from .effects import parse_effect, parse_noise
    from .results import Simulation
    if samples is not None and samples < MIN_SAMPLES:
        raise InputError(f"{samples} samples: at least {MIN_SAMPLES} are needed", key="--samples")
    mechanism = load(mech)
    named = [parse_effect(e, mechanism, values=True) if isinstance(e, str) else e for e in effects]
    keys = {(s.kind, s.coordinate) for s in named}
    if len(keys) < len(named):
        raise InputError("an effect is named twice (same kind and coordinate)", key="--effect")
    _, known = split_effects(mechanism, [])
    hidden = [s for s in known if (s.kind, s.coordinate) not in keys] + named
    for path in (output, truth):
        if same_file(path, mechanism.path):
            raise InputError("would overwrite the mechanism file", file=path)
    if truth and same_file(truth, output):
        raise InputError("the truth and the data would be the same file", file=truth)
    sd = parse_noise(noise) if isinstance(noise, str) else noise
    _say(progress, f"simulating {mechanism.name}")
    data, truth_data = run_simulation(mechanism, samples=samples, noise_sd=sd, seed=seed, effects=hidden,
                                      random_inertia=random_inertia)
    if output is not None:
        _say(progress, f"writing {output}")
        write_measured(output, data, derivatives=derivatives)
    if truth:
        atomic_write(truth, json.dumps(truth_data, indent=2) + "\n")
    return Simulation(data, truth_data, len(hidden), None if output is None else str(output),
                      None if truth is None else str(truth))


# ----- identify --------------------------------------------------------------------------
def identify(mech: MechanismLike, data: DataPaths, *, effects: Sequence[EffectLike] = (),
             solver: str = DEFAULT_SOLVER, solver_options: Mapping[str, Any] | None = None,
             validate: Sequence[PathText] = (), physical: bool = False,
             progress: Progress | None = None) -> "Fit":
    """Weighted least squares on ``mech``'s base parameters (those of ``solver``, with
    ``solver_options``) and the coefficients of ``effects`` (``"viscous_friction:q1"``,
    ``"coulomb_friction:*"``) from measured ``data`` (CSV files or recording descriptions,
    several fitted together). ``validate``: recordings to predict with the identified
    model. ``physical``: also physically consistent standard parameters (needs cvxpy)."""
    from baseparams.identify.base import BaseModel
    from baseparams.identify.fit import fitted, identify as fit, predict, split_effects, unfiltered
    from baseparams.recordings.recording import read_data

    from .effects import parse_effects
    from .results import Fit
    if physical:
        from baseparams.identify import physical as consistency     # cvxpy: an optional extra
        consistency.require_cvxpy()
    chosen = get_solver(solver)
    check_solver_options(chosen, solver_options or {})
    mechanism = load(mech)
    _say(progress, "reading the data")
    loaded = mechanism
    measured, mechanism = read_data(_paths(data), mechanism)
    fit_filter = measured.filters[0] if measured.filters else None      # validation on the fit's band (issue 44)
    others = [_validation(str(path), loaded, mechanism, fit_filter) for path in validate]
    texts = [e for e in effects if isinstance(e, str)]
    import numpy as np
    qd = np.asarray(measured.motion.qd, float)
    unmeasured = np.asarray(~measured.measured().any(axis=0) if measured.masked else
                            np.zeros(len(measured.coordinates), bool), dtype=bool)
    still = [c for j, c in enumerate(measured.coordinates) if not np.any(qd[:, j]) or unmeasured[j]]
    named = parse_effects(texts, mechanism, still) + [e for e in effects if not isinstance(e, str)]
    to_identify, known = split_effects(mechanism, named)
    _say(progress, f"base parameters ({solver})")
    result = run_solver(chosen, mechanism, solver_options)         # quiet: no inner progress lines
    base = BaseModel.from_result(result, mechanism)
    _say(progress, f"fitting {measured.count} samples")
    identification = fit(mechanism, measured, effects=to_identify, base=base, known=known)
    if still and any(":" in t and t.partition(":")[2].strip() == "*" for t in texts):
        identification.notes += (f"KIND:* left out {', '.join(still)}: held still in the data, or without a "
                                 "measured force (no effect to identify there)",)
    if physical:
        _say(progress, "physically consistent parameters (cvxpy)")
        _physical(identification, mechanism, base)
    on_its_data = fitted(identification, measured)
    on_its_data.nrms_unfiltered = unfiltered(identification, mechanism, measured, on_its_data).nrms
    predictions = [predict(identification, mechanism, other) for other in others]
    for prediction, other in zip(predictions, others):
        prediction.nrms_unfiltered = unfiltered(identification, mechanism, other, prediction).nrms
    identification.extras["nrms_unfiltered"] = dict(zip(measured.coordinates,
                                                        map(float, on_its_data.nrms_unfiltered)))
    if predictions and fit_filter is not None and len({(f["cutoff"], f["order"]) for f in measured.filters}) > 1:
        cutoffs = ", ".join(sorted({"%.4g" % f["cutoff"] for f in measured.filters}))
        identification.notes += (f"the fit's runs were filtered at {cutoffs} Hz: --validate recordings at the first "
                                 f"run's, {fit_filter['cutoff']:.4g} Hz",)
    identification.extras["rms"] = on_its_data.to_json()["rms"]
    identification.extras["rms_overall"] = on_its_data.overall_rms
    identification.extras["runs"] = list(measured.runs)
    if predictions:
        identification.extras["validation"] = [p.to_json() for p in predictions]
    identification.extras["known_effects"] = [
        {"kind": s.kind, "coordinate": s.coordinate, "values": {n: exact(v) for n, v in s.values.items()}}
        for s in identification.known]
    impossible = [f.name for f in identification.impossible if f.impossible]
    said = [f"{len(impossible)} estimate{'s' if len(impossible) > 1 else ''} no robot has: {', '.join(impossible)} "
            "(the report's IMPOSSIBLE estimates; JSON: impossible)"] if impossible else []
    far = [f"{f.name} = {f.value:.3g} +- {f.std:.2g}" for f in identification.impossible if f.beyond is not None]
    said += [f"{len(far)} estimate{'s' if len(far) > 1 else ''} beyond any physical scale: {', '.join(far)} (the "
             "data do not determine them, or are read wrong; JSON: beyond_physical_scale)"] if far else []
    return Fit(identification, on_its_data, predictions,
               warnings=list(result.warnings) + said + list(identification.warnings))


def exact(value: Any) -> str:
    """An exact number as its decimal string where it has one (``0.3``), else ``p/q``."""
    from baseparams.model.expressions import exact_text
    try:
        return exact_text(Fraction(value))
    except (TypeError, ValueError):
        return str(value)


def _physical(identification: Any, mechanism: "Mechanism", base: Any) -> None:
    """Physically consistent standard parameters into ``identification`` (its ``physical``
    and ``extras["physical_fit"]``); cvxpy's own warnings are kept as the fit's warnings."""
    from baseparams.identify import physical as consistency
    from baseparams.dynamics.forces import standard_parameters
    prior, source = None, "least-norm parameters B^+ phi_b"
    if all(b.inertia is not None for b in mechanism.bodies):
        from baseparams.model.consistency import require_physical
        require_physical(mechanism, "identify --physical (the file's inertias are its prior)")
        prior, source = standard_parameters(mechanism), "the mechanism file's inertias"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        found = consistency.physical_fit(identification.base_estimates, base,
                                         std=identification.std[:base.rank], prior=prior)
    said = list(dict.fromkeys(" ".join(str(w.message).split()) for w in caught))
    identification.physical = consistency.physical_json(found, tuple(mechanism.parameters))
    identification.extras["physical_fit"] = {
        "max_deviation_std": found.max_deviation, "prior": source, "solver": found.solver,
        "status": found.status, "warnings": said,
        "min_pseudo_inertia_eigenvalue": dict(zip(map(str, mechanism.body_labels),
                                                  map(float, found.min_eigenvalues)))}


# ----- diagnose --------------------------------------------------------------------------
def diagnose(mech: MechanismLike, data: DataPaths, *, params: ResultLike | None = None,
             candidates: Sequence[str] | None = None, alpha: float = 0.05, folds: int = 5,
             holdout: float = 0.0, max_steps: int | None = None, write: PathText | None = None,
             baseline: DataPaths | None = None, urdf_dynamics: bool = False,
             progress: Progress | None = None) -> "Diagnosed | ChangeDiagnosed":
    """Name the effects ``mech``'s model misses on measured ``data``: the model is fitted
    (or held as given: ``params``, a mechanism file with the robot's inertias or an
    identify JSON), every candidate effect (``candidates``: ``KIND[:PLACE]``; default all)
    is tested, the most significant added, until none is. ``write``: a TOML file of the
    mechanism with the named effects. ``result.closed`` says whether the gap closed.

    ``baseline``: runs of the same robot before a change; then what changed between them
    and ``data`` is named instead (:func:`diagnose_change`). ``params`` may be the result of
    :func:`identify` itself (or its JSON dict) wherever a file's path is taken.
    ``urdf_dynamics``: hold a URDF's ``<dynamics damping friction>`` as known effects (by
    default they are set aside: placeholders are common, and the diagnosis finds friction
    itself)."""
    _check_result(params)
    if params is not None and result_json(params) is not None:
        with result_file(params, "identify-result.json") as path:
            return diagnose(mech, data, params=path, candidates=candidates, alpha=alpha, folds=folds,
                            holdout=holdout, max_steps=max_steps, write=write, baseline=baseline,
                            urdf_dynamics=urdf_dynamics, progress=progress)
    if baseline is not None:
        refused = [name for name, value in (("candidates", candidates), ("holdout", holdout),
                                            ("max_steps", max_steps), ("write", write)) if value]
        if refused or folds != 5:
            raise InputError("between recordings the change candidates are fixed and nothing is written: "
                             f"{', '.join(refused or ['folds'])} cannot be used with a baseline", key="--baseline")
        return diagnose_change(mech, data, baseline, params=params, alpha=alpha, urdf_dynamics=urdf_dynamics,
                               progress=progress)
    from dataclasses import replace

    from baseparams.diagnose.fixed import check_writable, write_fixed

    from baseparams.diagnose.workflow import diagnose_data
    from baseparams.diagnose.given import given_parameters
    from baseparams.recordings.recording import read_data

    from .results import Diagnosed
    paths = _paths(data)
    mechanism, set_aside = _without_urdf_dynamics(load(mech), urdf_dynamics)
    if write:
        check_writable(mechanism, write)          # before the run, not after it
    given = None
    replaced: list[str] = []
    if params:
        given = given_parameters(mechanism, str(params))
        known = given.effects
        if known:                 # an identify result's effects: its totals, as identify overrode the model's
            keys = {(e.kind, e.coordinate) for e in known}
            replaced = [f"{e.kind}:{e.coordinate}" for e in mechanism.effects if (e.kind, e.coordinate) in keys]
            mechanism = replace(mechanism, effects=tuple(e for e in mechanism.effects
                                                         if (e.kind, e.coordinate) not in keys) + tuple(known))
    _say(progress, "reading the data")
    measured, mechanism = read_data(paths, mechanism)
    _say(progress, f"testing candidate effects on {measured.count} samples")
    result = diagnose_data(mechanism, measured, selection=list(candidates) if candidates else None, alpha=alpha,
                           folds=folds, holdout=holdout, max_steps=max_steps, given=given)
    if replaced:
        result.notes.append(f"--params {params}: its identified values replace the model's own {', '.join(replaced)}")
    if given is not None and result.verdict in ("partly explained", "unexplained"):
        _baseline_hint(given, str(params), paths, result.notes)
    elif given is not None and _held_lack(given) >= HELD_LACK:
        worst = max((c for c, v in given.fit_nrms.items() if v == v), key=lambda c: given.fit_nrms[c])
        result.notes.append(f"--params {params}: that identification leaves NRMS {given.fit_nrms[worst]:.2g} of the "
                            f"force on its own run ({worst}): a change smaller than what it lacks is not told from "
                            "that lack here")
        _baseline_hint(given, str(params), paths, result.notes)
    result.notes.extend(set_aside)
    written = None
    if write:
        existing = {(e.kind, e.coordinate) for e in mechanism.effects}
        named = [e for e in result.named() if (e.kind, e.coordinate) not in existing]
        for entry in result.effects:          # a correction of the model's own known value
            if entry.get("known"):
                result.notes.append(
                    f"--write: {entry['kind']}:{entry['coordinate']} corrects the model's own "
                    + ", ".join(f"{k} = {v:.6g}" for k, v in entry["known"].items()) + ": set "
                    + ", ".join(f"{k} = {v + _value_of(entry, k):.6g}" for k, v in entry["known"].items())
                    + f" in {mechanism.path} yourself (--write appends new effects only)")
        if named:
            write_fixed(mechanism, named, write, origin=f"data {', '.join(paths)}")
            written = str(write)
        else:
            result.notes.append(f"--write: no new mechanism effect named, {write} not written")
    from .render import coordinate_kinds
    return Diagnosed(result, written, coordinate_kinds(mechanism))


# the effects a URDF reader makes of <dynamics damping friction>
URDF_DYNAMICS = ("viscous_friction", "coulomb_friction")


def _without_urdf_dynamics(mechanism: "Mechanism", hold: bool) -> tuple["Mechanism", list[str]]:
    """``mechanism`` without the known frictions its URDF's ``<dynamics>`` gave (unless
    ``hold``), and the note saying so. Why: robot URDFs carry placeholders (TIAGo: damping on
    every joint); held as known, the diagnosis started from a gap of 22 and spent its names
    "correcting" them (torso viscous -990.7)."""
    from dataclasses import replace
    from baseparams.diagnose.candidates import known_effect
    path = str(mechanism.path or "")
    if hold or not path.lower().endswith(".urdf"):
        return mechanism, []
    gone = [e for e in mechanism.effects if e.kind in URDF_DYNAMICS and known_effect(e)]
    if not gone:
        return mechanism, []
    kept = tuple(e for e in mechanism.effects if e not in gone)
    joints = sorted({e.coordinate for e in gone})
    note = (f"{Path(path).name}: its <dynamics> damping and friction on {len(joints)} joint(s) "
            f"({', '.join(joints[:4])}{' ...' if len(joints) > 4 else ''}) are not held as known (URDFs often carry "
            "placeholders); the diagnosis finds friction itself. --urdf-dynamics holds them")
    return replace(mechanism, effects=kept), [note]


def _value_of(entry: dict, coefficient: str) -> float:
    """A named effect's estimated coefficient (its report entry)."""
    return float(entry["coefficients"][coefficient]["value"])


def read(mech: MechanismLike, data: DataPaths) -> "MeasuredData":
    """Measured data (CSV files or recording descriptions) as the fit reads it."""
    from baseparams.recordings.recording import read_data
    return read_data(_paths(data), load(mech))[0]


# A held identification leaving this NRMS of the force on its own run (its largest coordinate)
# hides changes of that size: said beside an exit-0 verdict. Why: the real Kinova repeat held
# at NRMS 0.45-0.73 gave "nothing missing" with a 0.5 kg load added (--baseline names it).
HELD_LACK = 0.1


def _held_lack(given: "Given") -> float:
    """The largest NRMS a held identification leaves on its own run (0 when not known)."""
    values = [v for v in given.fit_nrms.values() if v == v]
    return max(values, default=0.0)


def _baseline_hint(given: "Given", params: str, paths: list, notes: list[str]) -> None:
    """When a diagnosis against a held identify result leaves structure and that result's own
    recordings are at hand, say that ``--baseline`` with them tells what changed: there what
    both runs lack cancels, which a held result's residual measures only in size."""
    from baseparams.diagnose.given import held_recordings
    runs = [r for r in held_recordings(given, params) if r not in {str(p) for p in paths}]
    if runs:
        notes.insert(0, "the held identification's own recordings are here: `--baseline "
                     + " ".join(runs) + "` (without --params) compares the two runs directly, and what both "
                     "lack cancels there")


def diagnose_change(mech: MechanismLike, changed: DataPaths, baseline: DataPaths, *, params: ResultLike | None = None,
                    alpha: float = 0.05, urdf_dynamics: bool = False,
                    progress: Progress | None = None) -> "ChangeDiagnosed":
    """What changed between the ``baseline`` runs and the ``changed`` runs of one robot (a
    payload, a gain, a friction, a delay): one model shared by both (fitted on the baseline,
    or ``params`` held as given), what both lack cancelled between samples in the same
    state, the change's candidates tested on the changed runs only
    (:mod:`baseparams.diagnose.change`). ``result.closed``: nothing changed, or the named
    changes explain the difference. ``params``: a path, or :func:`identify`'s result itself.
    ``urdf_dynamics``: as for :func:`diagnose`."""
    _check_result(params)
    if params is not None and result_json(params) is not None:
        with result_file(params, "identify-result.json") as path:
            return diagnose_change(mech, changed, baseline, params=path, alpha=alpha, urdf_dynamics=urdf_dynamics,
                                   progress=progress)
    from dataclasses import replace

    from baseparams.diagnose.change import diagnose_change as run
    from baseparams.diagnose.given import given_parameters
    from baseparams.recordings.recording import read_data

    from .render import coordinate_kinds
    from .results import ChangeDiagnosed
    changed_paths, baseline_paths = _paths(changed), _paths(baseline)
    if not baseline_paths:
        raise InputError("give at least one baseline run", key="--baseline")
    mechanism, set_aside = _without_urdf_dynamics(load(mech), urdf_dynamics)
    given = None
    if params:
        given = given_parameters(mechanism, str(params))
        if given.effects:         # an identify result's effects: its totals, as identify overrode the model's
            keys = {(e.kind, e.coordinate) for e in given.effects}
            mechanism = replace(mechanism, effects=tuple(e for e in mechanism.effects
                                                         if (e.kind, e.coordinate) not in keys) + tuple(given.effects))
    _say(progress, "reading the baseline")
    before, mechanism_before = read_data(baseline_paths, mechanism)
    _say(progress, "reading the changed runs")
    # with the baseline's low-pass, so that both sides see one filter and the same motion pairs:
    # a window of the Kinova repeat's second run (0.3-1.6 s, joint 1 at near-constant speed)
    # read its positions' bandwidth as 54.5 Hz (its speed ripple), kept 200 Hz against the
    # baseline's 41, only 27 % of its samples paired, and two bodies were named
    after, mechanism_after = read_data(changed_paths, mechanism, fit_filter=before.filters[0] if before.filters
                                       else None)
    if mechanism_before.motors != mechanism_after.motors or mechanism_before.gravity != mechanism_after.gravity:
        raise InputError("the baseline's descriptions declare other motors or another gravity than the changed "
                         "runs': describe both alike", key="--baseline")
    _say(progress, f"testing changes on {after.count} samples against {before.count}")
    result = run(mechanism_after, before, after, given=given, alpha=alpha)
    result.notes.extend(set_aside)
    result.notes = [f"baseline: {n}" for n in before.notes] + [f"changed: {n}" for n in after.notes] + result.notes
    return ChangeDiagnosed(result, coordinate_kinds(mechanism_after))

"""What a diagnosis does not recompute for each dataset: the model's columns at the data's
samples, the known forces and the candidates (:class:`Problem`, made by :func:`prepare`). Why
a module of its own: a campaign reuses one problem for many datasets on the same motion, and
the checks of :mod:`.gates` and :mod:`.verdict` read it.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from baseparams.diagnose.candidates import known_effect, library, parse_selection
from baseparams.diagnose.derived import KINDS as DERIVED_KINDS
from baseparams.diagnose.selection import Candidate
from baseparams.dynamics.evaluator import Sample
from baseparams.dynamics.forces import Motion, design, effect_values, effects_design, evaluate, independent_names
from baseparams.errors import InputError
from baseparams.identify.fit import measured_design
from baseparams.model.mechanism import Mechanism
from baseparams.recordings.data import MeasuredData


@dataclass
class Problem:
    """The model's columns at the data's samples, computed once (a campaign reuses them
    for many datasets on the same motion): ``inertial`` (N, f, P) the columns fitted to the
    data (the standard parameters plus the mechanism's effects with unknown coefficients;
    with a given simulation only those effects); ``known`` (N, f) the force the model
    already gives (known effects, known payloads, and the given simulation's torque);
    the candidates; ``qd`` (N, f) the independent speeds; ``bodies`` (N, f, P) the standard
    columns when the inertial parameters are given (body and payload candidates), else None."""
    mechanism: Mechanism
    coordinates: tuple[str, ...]
    t: np.ndarray
    inertial: np.ndarray
    known: np.ndarray
    candidates: list[Candidate]
    notes: list[str] = field(default_factory=list)
    qd: np.ndarray | None = None
    bodies: np.ndarray | None = None
    given: np.ndarray | None = None            # the given standard parameters (P,), or None
    wanted: set | None = None                  # derived candidates to build (None: all)
    # white noise's autocorrelation at the fit's lags after the recording's filter and
    # decimation (MeasuredData.noise_correlation), None when nothing was filtered
    correlation: np.ndarray | None = None
    given_masses: bool = True                  # whether given's body masses are the bodies' (given.Given)
    # an identify result held as given: E (r, P) to its base parameters and their covariance (r, r)
    given_uncertainty: tuple[np.ndarray, np.ndarray] | None = None
    quanta: np.ndarray | None = None           # (f,) the forces' quantisation steps (MeasuredData.quanta)
    # an identify result held as given: its residual NRMS and RMS on its own run (f,), NaN where unknown
    held_nrms: np.ndarray | None = None
    held_rms: np.ndarray | None = None


def prepare(mechanism: Mechanism, motion: Motion, sample: Sample | None = None,
            selection: Sequence[str] | None = None, data: MeasuredData | None = None,
            given: np.ndarray | None = None) -> Problem:
    """The inertial and candidate columns along ``motion``; ``selection``: ``KIND[:COORD]``
    strings restricting the candidates (None: every registered effect on every coordinate
    and motor, and the derived candidates of :mod:`.derived`). With measured ``data`` every
    column is reduced to the fit's rows as its torques were (parallel filtering), and its
    known payloads' forces count as known. ``given``: standard parameters (P,) held as
    given (diagnose a simulation): their torque is known, and bodies become candidates."""
    sample = sample if sample is not None else evaluate(mechanism, motion)
    pairs = parse_selection(mechanism, selection, given is not None) if selection else None
    known_specs = [e for e in mechanism.effects if known_effect(e)]
    fitted_specs = [e for e in mechanism.effects if not known_effect(e)]
    t = np.asarray(motion.t, float)
    qd = np.asarray(motion.qd, float)
    reduce = None
    correlation = None
    if data is not None:
        correlation = data.noise_correlation() if data.reduced else None
        inertial, fitted, known = measured_design(mechanism, data, fitted_specs, known_specs)   # as identify's
        reduce, t = data.reduce, data.t
        qd = qd[data.kept_rows()]
    else:
        inertial, fitted = design(mechanism, motion, fitted_specs, sample)
        known = effects_design(mechanism, sample, motion.count, known_specs).matrix @ \
            effect_values(mechanism, known_specs) if known_specs else np.zeros(inertial.matrix.shape[:2])
    registered = None if pairs is None else [(k, c) for k, c in pairs if k not in DERIVED_KINDS]
    candidates, notes = library(mechanism, sample, motion.count, registered, reduce) \
        if registered is None or registered else ([], [])
    if known_specs:
        notes.append("known effects subtracted: " + ", ".join(f"{e.kind}:{e.coordinate}" for e in known_specs))
    if fitted_specs:
        notes.append("effects fitted with the inertial model: "
                     + ", ".join(f"{e.kind}:{e.coordinate}" for e in fitted_specs))
    wanted = None if pairs is None else {(k, c) for k, c in pairs if k in DERIVED_KINDS}
    if not candidates and wanted == set():
        raise InputError("no candidate effects left to test (every selected effect is already "
                         "in the mechanism)", key="--candidates")
    quanta = data.quanta if data is not None else None
    if given is not None:
        given = np.asarray(given, dtype=float)
        known = known + inertial.matrix @ given
        notes.append("the inertial parameters are held as given (--params): bodies, payloads and "
                     "torque gains are candidates")
        return Problem(mechanism, independent_names(mechanism), t, fitted.matrix, known, candidates, notes,
                       qd, inertial.matrix, given, wanted, correlation, quanta=quanta)
    model = np.concatenate([inertial.matrix, fitted.matrix], axis=-1)
    return Problem(mechanism, independent_names(mechanism), t, model, known, candidates, notes, qd,
                   None, None, wanted, correlation, quanta=quanta)

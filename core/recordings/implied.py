"""The project's CSV layout read as a recording: the description its header implies.

A CSV in the layout of docs/design.md (``t``, ``q_c``, optional ``qd_c``/``qdd_c``,
``tau_c``) whose derivatives must be estimated from irregular stamps cannot go through
Savitzky-Golay; it is read as a recording description would read the same columns
(``time = "t"``, ``[position] c = "q_c"``, ``[velocity]`` and ``[acceleration]`` when
given, ``[torque] c = "tau_c"``): resampled to be filtered and differentiated, taken back
to each sample's own time, filtered and decimated in parallel. One pipeline, so the two
ways of reading the same samples cannot disagree (tests/test_logs_round_two.py compares
them). Why: the Panda's samples in the project's layout (irregular stamps, a measured
velocity, no acceleration) were refused while the description path read them (issue 44).
"""

import os
from pathlib import Path

from baseparams.dynamics.forces import independent_names
from baseparams.model.mechanism import Mechanism
from baseparams.recordings.data import MeasuredData, _read_text, read_columns
from baseparams.recordings.recording import describe, read_described


def implied_description(path: str | os.PathLike, mechanism: Mechanism) -> dict:
    """The description (as parsed TOML) that reads the CSV at ``path`` in the project's layout."""
    path = Path(path)
    header, _, _ = read_columns(str(path), _read_text(str(path)), wanted=())
    coordinates = independent_names(mechanism)
    data: dict = {"recording": {"time": "t", "time_unit": "s", "delimiter": ","},
                  "runs": [{"name": str(path), "file": {"path": path.name}}],
                  "position": {c: f"q_{c}" for c in coordinates},
                  "torque": {c: f"tau_{c}" for c in coordinates}}
    for quantity, prefix in (("velocity", "qd"), ("acceleration", "qdd")):
        if all(f"{prefix}_{c}" in header for c in coordinates):
            data[quantity] = {c: f"{prefix}_{c}" for c in coordinates}
    return data


def read_layout(path: str | os.PathLike, mechanism: Mechanism, *, check_kinematics: bool = True,
                fit_filter: dict | None = None, why: str = "irregular time stamps") -> MeasuredData:
    """The CSV at ``path`` (the project's layout, already checked field by field) through the
    recording pipeline with its implied description, with a note saying so and ``why``
    (``fit_filter``: as :func:`~.recording.read_described` takes it: a --validate recording
    filtered as the fit's data were)."""
    data = implied_description(path, mechanism)
    measured, _ = read_described(describe(data, str(path), mechanism), check_kinematics=check_kinematics,
                                 fit_filter=fit_filter)
    given = [q for q in ("velocity", "acceleration") if q in data]
    measured.notes = (f"{why}: read as a recording with the description its columns imply (time t, "
                      f"positions q_c{''.join(', ' + q + 's ' + ('qd_c' if q == 'velocity' else 'qdd_c') for q in given)}"
                      ", torques tau_c; docs/identification.md, \"One pipeline\")",) + measured.notes
    measured.path = str(path)
    return measured

"""The project's CSV layout read as a recording: the description its header implies.

A CSV in the layout of docs/design.md (``t``, ``q_c``, optional ``qd_c``/``qdd_c``,
``tau_c``) whose derivatives must be estimated from irregular stamps cannot go through
Savitzky-Golay; it is read as a recording description would read the same columns
(``time = "t"``, ``[position] c = "q_c"``, ``[velocity]`` and ``[acceleration]`` when
given, ``[torque] c = "tau_c"``): resampled to be filtered and differentiated, taken back
to each sample's own time, filtered and decimated in parallel. One pipeline, so the two
ways of reading the same samples cannot disagree (tests/test_logs_round_two.py compares
them; :func:`baseparams.recordings.recording.read_data` reads the file so). Why: the Panda's
samples in the project's layout (irregular stamps, a measured velocity, no acceleration)
were refused while the description path read them (issue 44).
"""

import os
from pathlib import Path

from baseparams.dynamics.forces import independent_names
from baseparams.model.mechanism import Mechanism
from baseparams.recordings.delimited import _read_text, read_columns


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


def implied_note(description: dict, why: str) -> str:
    """The note saying that a CSV in the project's layout was read through the recording
    pipeline, and why (irregular stamps; a --validate recording filtered as the fit's data)."""
    given = [q for q in ("velocity", "acceleration") if q in description]
    return (f"{why}: read as a recording with the description its columns imply (time t, positions q_c"
            + "".join(f", {q}s {'qd_c' if q == 'velocity' else 'qdd_c'}" for q in given)
            + ", torques tau_c; docs/identification.md, \"One pipeline\")")

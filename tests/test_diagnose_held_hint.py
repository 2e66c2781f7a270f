"""diagnose --params: when structure remains and the held identification's own recordings are
at hand, the report points to --baseline with them (what both runs lack cancels there)."""

import json

import numpy as np

import baseparams as bp
from baseparams.io.loader import resolve
from baseparams.recordings.data import write_measured
from baseparams.recordings.simulate import simulate_change


def _diagnosed(tmp_path, move_away: bool):
    mechanism = resolve("planar_2r")
    before, after, _ = simulate_change(mechanism, samples=800, seed=1, payload=0.0)
    q = after.motion.q
    rms = np.sqrt(np.mean(after.tau[:, 0] ** 2))
    after.tau[:, 0] += 0.3 * rms * np.sin(3 * q[:, 0] + 2 * q[:, 1])    # no candidate has this form
    base, changed, held = tmp_path / "base.csv", tmp_path / "changed.csv", tmp_path / "held.json"
    write_measured(base, before)
    write_measured(changed, after)
    held.write_text(json.dumps(bp.identify("planar_2r", str(base)).to_json()))
    if move_away:
        base.unlink()
    return bp.diagnose("planar_2r", str(changed), params=str(held)).to_json(), str(base)


def test_structure_left_points_to_the_held_runs_recording(tmp_path):
    report, base = _diagnosed(tmp_path, move_away=False)
    assert report["verdict"] in ("partly explained", "unexplained")
    hints = [n for n in report["notes"] if "--baseline" in n and "own recordings" in n]
    assert len(hints) == 1 and base in hints[0]


def test_no_pointer_when_the_recording_is_gone(tmp_path):
    report, _ = _diagnosed(tmp_path, move_away=True)
    assert report["verdict"] in ("partly explained", "unexplained")
    assert not [n for n in report["notes"] if "own recordings" in n]


def test_a_description_run_is_found_with_its_run_name(tmp_path):
    """An identify result of a description's run names it FILE#run in its ``data``: the file is
    looked for, the run kept; a missing file, or one only beside the result, as it is."""
    from baseparams.diagnose.given import Given, held_recordings
    description = tmp_path / "logs" / "recording.toml"
    description.parent.mkdir()
    description.write_text("")
    beside = tmp_path / "results" / "base.csv"
    beside.parent.mkdir()
    beside.write_text("")
    given = Given(np.zeros(1), recordings=(f"{description}#first", "gone.csv#x", "base.csv"))
    assert held_recordings(given, str(tmp_path / "results" / "held.json")) == \
        [f"{description}#first", str(beside)]

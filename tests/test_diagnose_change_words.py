"""The change report's verdict says what it can claim: between other motions (nothing paired)
the difference holds what the shared model misses on motions it was not fitted to, so the
verdict does not say the runs agree within their noise, nor that the named changes explain
the difference (the real TX40's halves with a 2 kg load's torque added: the gap 1.36 -> 1.34)."""

from pathlib import Path

import baseparams as bp
from baseparams.api.render import CHANGE_VERDICTS

TX40 = Path(__file__).parent / "data" / "tx40"


def test_other_motions_nothing_changed_is_not_within_noise():
    result = bp.diagnose(str(TX40 / "tx40_mdh_modified.urdf"), str(TX40 / "recording.toml") + "#last",
                         baseline=str(TX40 / "recording.toml") + "#first")
    report = result.to_json()
    assert report["verdict"] == "nothing changed" and not report["pairing"]["paired"]
    head = result.to_text().splitlines()[0]
    assert "what the shared model misses on motions it was not fitted to" in head, head
    assert CHANGE_VERDICTS["nothing changed"] not in head and report["gap"]["before"] > 0.5

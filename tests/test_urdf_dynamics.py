"""A robot's own URDF as the user's model (issue 48): its ``<dynamics>`` placeholders are
set aside by default, held only when the user says so (``--urdf-dynamics``)."""

from pathlib import Path


def test_a_urdfs_placeholder_dynamics_are_set_aside_unless_held(tmp_path):
    """A URDF's <dynamics damping> placeholders (50 N m s/rad on every joint, as robot URDFs
    carry) are not held as known by default: the diagnosis names the true viscous friction
    (0.5 on shoulder_lift_joint, simulated without placeholders) and nothing that "corrects"
    a placeholder; --urdf-dynamics holds them, and the diagnosis must then correct them."""
    import baseparams as bp
    source = (Path(__file__).parent / "data" / "urdf" / "ur5.urdf").read_text()
    truth = tmp_path / "ur5.urdf"
    truth.write_text(source)
    placeholders = tmp_path / "ur5_placeholders.urdf"
    placeholders.write_text(source.replace('damping="0.0"', 'damping="50"'))
    bp.simulate(str(truth), output=tmp_path / "run.csv", effects=["viscous_friction:shoulder_lift_joint=0.5"],
                noise=0.01, samples=1500, seed=2)
    report = bp.diagnose(str(placeholders), str(tmp_path / "run.csv"), candidates=["viscous_friction"])
    named = {(e["kind"], e["coordinate"]): e for e in report.to_json()["effects"]}
    assert list(named) == [("viscous_friction", "shoulder_lift_joint")], list(named)
    assert abs(named[("viscous_friction", "shoulder_lift_joint")]["value"] - 0.5) < 0.05
    assert any("<dynamics>" in note and "--urdf-dynamics" in note for note in report.to_json()["notes"])
    held = bp.diagnose(str(placeholders), str(tmp_path / "run.csv"), candidates=["viscous_friction"],
                       urdf_dynamics=True)
    corrected = [e["coordinate"] for e in held.to_json()["effects"]]
    assert len(corrected) >= 5, corrected          # every placeholder is a wrong known value


def test_cli_flag_holds_the_urdfs_dynamics(tmp_path):
    import json
    from click.testing import CliRunner
    import baseparams as bp
    from baseparams.cli import main
    source = (Path(__file__).parent / "data" / "urdf" / "ur5.urdf").read_text()
    urdf = tmp_path / "ur5.urdf"
    urdf.write_text(source.replace('damping="0.0"', 'damping="50"'))
    bp.simulate(str(urdf), output=tmp_path / "run.csv", samples=600, seed=1, noise=0.01)   # placeholders true here
    args = ["diagnose", str(urdf), str(tmp_path / "run.csv"), "--candidates", "viscous_friction", "--format", "json"]
    held = CliRunner().invoke(main, [*args, "--urdf-dynamics"])
    assert held.exit_code in (0, 1) and not any("<dynamics>" in n for n in json.loads(held.stdout)["notes"])
    assert json.loads(held.stdout)["effects"] == []            # held and true: nothing to correct
    aside = CliRunner().invoke(main, args)
    assert any("<dynamics>" in n for n in json.loads(aside.stdout)["notes"])

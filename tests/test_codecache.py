"""The generated ball regressor's code kept on disk (core/dynamics/codecache.py, issue 47):
W evaluated from the stored code is W evaluated from freshly generated code, ball for ball
(midpoints and radii); the key follows the mechanism's content; an unreadable file is
regenerated; ``off`` and an unwritable folder leave no file and change nothing."""

import pytest
from flint import ctx

from baseparams.dynamics import codecache, codegen
from baseparams.dynamics.observation import observation_matrix
from baseparams.dynamics.trajectory import Trajectory
from baseparams.io.loader import parse_mechanism
from baseparams.model import generate
from baseparams.numeric.backends import Arb

BODIES = codecache.FROM_BODIES


def chain(seed: int = 4, bodies: int = BODIES):
    return parse_mechanism(generate.serial_chain(seed, bodies=bodies), f"chain{seed}.toml")


def fresh() -> None:
    """Forget what this process generated (the disk is all that is left)."""
    codegen._SCALAR.clear()
    codegen._SCALAR_CONSTANTS.clear()
    codegen._traced.cache_clear()
    codegen._nonzero_columns.cache_clear()


def balls(mech) -> list[tuple[str, str]]:
    """W at 30 digits on 3 samples, each entry as (midpoint, radius) strings."""
    W = observation_matrix(mech, Arb(30), Trajectory.default(mech, samples=3))[0]
    with ctx.workdps(40):
        return [(x.mid().str(40, radius=False), x.rad().str(5, radius=False)) for x in W.entries()]


def test_stored_code_gives_the_same_balls(tmp_path, monkeypatch):
    mech = chain()
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", "off")
    fresh()
    generated = balls(mech)
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", str(tmp_path))
    fresh()
    assert balls(mech) == generated                         # generated and stored
    assert len(list((tmp_path / "generated").glob("*.pickle"))) == 1
    fresh()
    monkeypatch.setattr(codegen, "_traced", lambda *a: pytest.fail("traced again: the stored code was not used"))
    again = parse_mechanism(generate.serial_chain(4, bodies=BODIES), "elsewhere/chain4.toml")
    assert balls(again) == generated                        # read back, in a mechanism loaded anew


def test_key_follows_the_content(monkeypatch):
    a, b, other = chain(4), chain(4), chain(5)
    assert codecache.key(a, "regressor") == codecache.key(b, "regressor")
    assert codecache.key(a, "regressor") != codecache.key(other, "regressor")
    assert codecache.key(a, "regressor") != codecache.key(a, "closure")
    text = generate.serial_chain(4, bodies=BODIES)
    moved = text.replace('"-9.81"', '"-9.8"')               # gravity: one number the code holds
    assert moved != text
    assert codecache.key(parse_mechanism(moved, "x.toml"), "regressor") != codecache.key(a, "regressor")
    assert codecache.key(chain(4, bodies=BODIES - 1), "regressor") is None      # too small to pay


def test_unreadable_file_is_regenerated(tmp_path, monkeypatch):
    mech = chain()
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", "off")
    fresh()
    generated = balls(mech)
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", str(tmp_path))
    folder = tmp_path / "generated"
    folder.mkdir()
    (folder / f"{codecache.key(mech, 'regressor, scalar')}.pickle").write_bytes(b"not a pickle")
    fresh()
    assert balls(mech) == generated
    assert codecache.load(codecache.key(mech, "regressor, scalar")) is not None     # rewritten


@pytest.mark.parametrize("setting", ["off", ""])
def test_off_writes_nothing(tmp_path, monkeypatch, setting):
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", setting)
    monkeypatch.chdir(tmp_path)
    assert codecache.directory() is None
    fresh()
    balls(chain())
    assert not list(tmp_path.rglob("*"))


def test_unwritable_folder_changes_nothing(tmp_path, monkeypatch):
    blocker = tmp_path / "a file"
    blocker.write_text("")
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", str(blocker))      # generated/ cannot be made under a file
    mech = chain()
    fresh()
    first = balls(mech)
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", "off")
    fresh()
    assert balls(mech) == first


def test_prune_keeps_the_newest(tmp_path, monkeypatch):
    monkeypatch.setattr(codecache, "KEEP", 3)
    monkeypatch.setenv("BASEPARAMS_CACHE_DIR", str(tmp_path))
    for k in range(5):
        codecache.store(f"k{k}", k)
        path = tmp_path / "generated" / f"k{k}.pickle"
        if path.exists():
            import os
            os.utime(path, ns=(10 ** 18 + k, 10 ** 18 + k))     # distinct times whatever the clock's resolution
    left = sorted(p.stem for p in (tmp_path / "generated").glob("*.pickle"))
    assert left == ["k2", "k3", "k4"]
    assert codecache.load("k4") == 4

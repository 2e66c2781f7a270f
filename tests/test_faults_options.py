"""Solver options against their declared ranges (issue 24, item 1): a degenerate value
(a ladder step of 0 digits, a rank above the parameter count, a seed of -1) is refused with
exit 2 and one ``error:`` line naming the option, before any work, and never gives a result.

The ranges live in the declarations (``SolverOption.minimum/maximum/length/increasing/
unique``) and are checked by the shared ``check_options``; these tests hold every built-in
solver to them, through the library and through the command line.
"""

import pytest
from click.testing import CliRunner

from baseparams import registry
from baseparams.cli.commands import main
from baseparams.errors import InputError
from baseparams.io.loader import resolve
from baseparams.solvers.protocol import SolverOption, check_options, options_from_text
from baseparams.solvers.run import run_solver

SOLVERS = ("dp", "vp", "exact", "symbolic")


def solver(name):
    return registry.solvers()[name].item


def cli(*args):
    return CliRunner().invoke(main, list(args))


# ----- the CLI: exit 2, one line naming the option, nothing on stdout ----------------------
BAD = [
    ("vp", "ladder=0", "ladder"),                   # issue 24: printed rank 0 with exit 0
    ("vp", "ladder=-5,30", "ladder"),               # exit 3 (prec must be >= 2)
    ("vp", "ladder=30,10000000", "ladder"),         # no cap, unlike --digits
    ("vp", "ladder=60,30", "ladder"),               # not increasing
    ("vp", "ladder=", "ladder"),                    # empty: IndexError
    ("vp", "digits=100000", "digits"),              # above --digits' cap
    ("vp", "digits=9", "digits"),
    ("vp", "kept=1000", "kept"),                    # IndexError
    ("vp", "kept=-1", "kept"),                      # a negative index read from the end
    ("vp", "kept=0,0", "kept"),
    ("vp", "kept=0,1,2,3,4,5,6,7,8,9", "kept"),     # dependent columns: ValueError, exit 3
    ("vp", "kept=1", "kept"),                       # fewer columns than the rank: rank 1 printed
    ("vp", "seed=-1", "seed"),
    ("vp", "seed=1_0", "seed"),                     # int() reads "1_0" as 10
    ("vp", "seed=\u0663", "seed"),                  # an Arabic-Indic 3
    ("vp", "samples=1", "samples"),
    ("vp", "samples=2000000", "samples"),
    ("dp", "rank=1000", "rank"),                    # issue 24: exit 3 (IndexError)
    ("dp", "rank=0", "rank"),                       # no base parameter at all
    ("dp", "rank=11", "rank"),                      # pendulum has 10 parameters
    ("dp", "seed=99999999999999999999", "seed"),
    ("dp", "digits=5", "digits"),
    ("exact", "samples=0", "samples"),
    ("exact", "samples=1000001", "samples"),
    ("exact", "seed=-3", "seed"),
    ("symbolic", "digits=1000000", "digits"),       # hung
    ("symbolic", "samples=10000000", "samples"),
    ("symbolic", "seed=1e3", "seed"),
]


@pytest.mark.parametrize("name, option, key", BAD, ids=[f"{n}-{o}" for n, o, _ in BAD])
def test_a_degenerate_option_is_refused_with_exit_2(name, option, key):
    result = cli("solve", "pendulum", "--solver", name, "-O", option)
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = [line for line in result.stderr.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1 and f"option {key!r}" in lines[0], result.stderr
    assert "Traceback" not in result.output and "internal error" not in result.stderr
    assert result.stdout == ""                       # no result printed


def test_dp_rank_above_the_rows_of_w_is_refused():
    """W's row count is known only once W is built: 2 samples give W 2 x 10 (was an
    OverflowError, exit 3)."""
    result = cli("solve", "pendulum", "--solver", "dp", "-O", "rank=3", "-O", "samples=2")
    assert result.exit_code == 2 and "option 'rank' must be at most 2" in result.stderr
    assert result.stdout == ""


def test_values_inside_the_range_still_solve():
    result = cli("solve", "pendulum", "--solver", "vp", "-O", "ladder=30,60", "-O", "seed=0",
                 "--format", "json")
    assert result.exit_code == 0, result.output
    assert '"rank": 3' in result.stdout
    result = cli("solve", "pendulum", "--solver", "dp", "-O", "rank=3")
    assert result.exit_code == 0 and "rank 3" in result.stdout


# ----- the library: one home for the range --------------------------------------------------
@pytest.mark.parametrize("name", SOLVERS)
def test_every_number_option_declares_a_range(name):
    """Every int option (and every list of ints) is bounded on both sides, so no value a
    user can type reaches the solver unchecked."""
    for o in solver(name).options:
        if o.type is int or (o.type is tuple and o.item is int):
            assert o.minimum is not None and o.maximum is not None, (name, o.name)


@pytest.mark.parametrize("name", SOLVERS)
def test_run_solver_refuses_out_of_range_values(name):
    """A library caller that skips the CLI gets the same InputError from run_solver (the
    one sequence: options checked, applicability, then solve)."""
    with pytest.raises(InputError, match="option 'seed' must be at least 0"):
        run_solver(name, resolve("pendulum"), {"seed": -1})


def test_a_bound_that_depends_on_the_mechanism_needs_the_mechanism():
    dp = solver("dp")
    assert check_options(dp, {"rank": 1000})["rank"] == 1000          # not knowable yet
    with pytest.raises(InputError, match=r"at most 10 \(the number of parameters of pendulum\)"):
        check_options(dp, {"rank": 1000}, resolve("pendulum"))


class _Toy:
    name = "toy"
    options = (SolverOption("x", float, 1.0, minimum=0.0, maximum=2.0),
               SolverOption("xs", tuple, (1, 2), item=int, minimum=1, maximum=9, length=(1, 3), unique=True))


@pytest.mark.parametrize("given, want", [
    ({"x": float("nan")}, "a finite number"),
    ({"x": float("inf")}, "a finite number"),
    ({"x": -0.5}, "at least 0.0"),
    ({"x": 2.5}, "at most 2.0"),
    ({"xs": (1, 2, 3, 4)}, "1 to 3 items"),
    ({"xs": (3, 3)}, "without repeats"),
    ({"xs": (0,)}, "at least 1 (every item)"),
])
def test_declared_ranges_are_checked(given, want):
    with pytest.raises(InputError, match=want.replace("(", r"\(").replace(")", r"\)")):
        check_options(_Toy(), given)
    assert check_options(_Toy(), {"x": 2, "xs": [1, 9]}) == {"x": 2.0, "xs": (1, 9)}


@pytest.mark.parametrize("text", ["nan", "inf", "1_0", "\u0661", "0x10", "1e999999"])
def test_option_text_is_parsed_strictly(text):
    with pytest.raises(InputError):
        check_options(_Toy(), options_from_text(_Toy(), [f"x={text}"]))

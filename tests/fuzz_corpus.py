"""A fuzz corpus of bad mechanism files: mutations of every built-in file, deterministic
from a seed, each labelled with what a correct program must do with it.

Used by tests/test_fuzz.py (a small subset, in the test suite) and by
benchmarks/fuzz_mechanisms.py (the whole corpus, a table of outcomes).

Each :class:`Case` holds the bytes of one file and an expectation per command:
``"invalid"`` (must exit 2 with a message), ``"valid"`` (must exit 0) or ``"any"`` (exit 0
or 2 are both right, e.g. a truncation that happens to leave a valid file). Whatever the
expectation, a traceback, an exit code other than 0 and 2, or a run past the time limit
is a failure. Mutations work on the parsed TOML (re-written by a small writer) or, for
BOMs, junk bytes and truncation, on the file's bytes.
"""

import copy
import math
import random
import re
import resource
import signal
import subprocess
import sys
import time
import tomllib
import zlib
from dataclasses import dataclass
from decimal import Decimal
from pathlib import Path

MECHANISMS = Path(__file__).resolve().parent.parent / "mechanisms"
PARAMETER_KINDS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Ixz", "Iyy", "Iyz", "Izz")

EXTREME = ["1e999999999", "1e400", "-1e400", "1e-400", "10**100000000", "2**2**2**2**2**2", "9" * 5000,
           "0." + "0" * 5000 + "1", "(1+" * 150 + "1" + ")" * 150]
HUGE_BUT_PARSEABLE = ["1e300", "1e-300", "-1e300"]
NON_FINITE = ["nan", "inf", "-inf", "NaN", "Infinity", Decimal("NaN"), Decimal("Infinity"), Decimal("-Infinity")]
JUNK_TEXT = ["0.5\u200b", "\uff10.\uff15", "0,5", "1e", "--", "0.5 m", "L/", "\x00", "\u202e1", "ü"]


@dataclass(frozen=True)
class Case:
    name: str                 # "<mechanism>.<kind>.<n>": unique, usable as a file stem
    mechanism: str
    kind: str
    detail: str               # what was changed, for the report
    data: bytes
    show: str                 # "invalid" | "valid" | "any"
    solve: str

    def expect(self, command: str) -> str:
        return self.show if command == "show" else self.solve


# ----- a small TOML writer (enough for mechanism files) ---------------------------

def _bare_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _string(key)


def _string(text: str) -> str:
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ch == "\x7f":
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


class RawInteger(str):
    """An integer literal kept as its digits: CPython's int() and str() refuse more than 4300."""


def _value(value) -> str:
    if isinstance(value, RawInteger):
        return str.__str__(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, Decimal):
        if value.is_nan():
            return "nan"
        if value.is_infinite():
            return "-inf" if value < 0 else "inf"
        text = str(value)
        return text if any(c in text for c in ".eE") else text + ".0"
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_bare_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def dumps(data: dict) -> str:
    """TOML text for a mechanism-like document (sections, arrays of tables, inline values)."""
    lines = []
    for key, value in data.items():
        if not isinstance(value, (dict, list)) or (isinstance(value, list) and not
                                                   (value and all(isinstance(v, dict) for v in value))):
            lines.append(f"{_bare_key(key)} = {_value(value)}")
    for key, value in data.items():
        if isinstance(value, dict):
            lines += ["", f"[{_bare_key(key)}]"] + [f"{_bare_key(k)} = {_value(v)}" for k, v in value.items()]
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for item in value:
                lines += ["", f"[[{_bare_key(key)}]]"] + [f"{_bare_key(k)} = {_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


# ----- paths into the document ---------------------------------------------------

def _get(data, path):
    for step in path:
        data = data[step]
    return data


def _set(data, path, value):
    _get(data, path[:-1])[path[-1]] = value


def _delete(data, path):
    del _get(data, path[:-1])[path[-1]]


def _path_text(path) -> str:
    out = ""
    for step in path:
        out += f"[{step}]" if isinstance(step, int) else ("." if out else "") + str(step)
    return out


def _numeric_leaves(data):
    """Paths of every number-or-expression leaf (geometry, points, axes, masses, ...)."""
    paths = [("geometry", k) for k in data.get("geometry", {})]
    paths += [("mechanism", "gravity", i) for i in range(3) if "gravity" in data.get("mechanism", {})]
    for b, body in enumerate(data.get("bodies", [])):
        if "mass" in body:
            paths.append(("bodies", b, "mass"))
            paths += [("bodies", b, "com", i) for i in range(3)]
            paths += [("bodies", b, "inertia_com", i) for i in range(6)]
        for k in body.get("inertia", {}):
            paths.append(("bodies", b, "inertia", k))
    for j, joint in enumerate(data.get("joints", [])):
        for end in ("parent_frame", "child_frame"):
            for part in ("point", "axis", "ref"):
                if part in joint.get(end, {}):
                    paths += [("joints", j, end, part, i) for i in range(3)]
    for k in ("t_start", "t_end"):
        if k in data.get("trajectory", {}):
            paths.append(("trajectory", k))
    return paths


# ----- mutations: each returns (detail, data or bytes, show expectation, solve expectation) ----

def _delete_required(doc, rng):
    j = rng.randrange(len(doc["joints"]))
    b = rng.randrange(len(doc["bodies"]))
    choices = [("mechanism",), ("mechanism", "name"), ("bodies",), ("joints",), ("joints", j, "type"),
               ("joints", j, "parent"), ("joints", j, "child"), ("joints", j, "parent_frame"),
               ("joints", j, "child_frame", "point"), ("bodies", b, "label")]
    if "trajectory" in doc:
        choices.append(("trajectory", "q"))
    if "mass" in doc["bodies"][b]:
        choices += [("bodies", b, "com"), ("bodies", b, "inertia_com")]
    path = rng.choice(choices)
    _delete(doc, path)
    return f"deleted {_path_text(path)}", doc, "invalid", "invalid"


def _delete_trajectory(doc, rng):
    doc.pop("trajectory", None)
    return "deleted [trajectory]", doc, "valid", "invalid"


def _misspell_key(doc, rng):
    options = [(("mechanism",), "gravity", "gravit"), (("mechanism",), "name", "nmae")]
    for b, body in enumerate(doc["bodies"]):
        if "mass" in body:
            options.append((("bodies", b), "mass", "mas"))
        options.append((("bodies", b), "label", "lable"))
    for j in range(len(doc["joints"])):
        options += [(("joints", j), "coordinates", "coordinate"), (("joints", j), "type", "typ"),
                    (("joints", j), "child_frame", "child_fram"), (("joints", j, "parent_frame"), "axis", "axes"),
                    (("joints", j), "limits", "limit")]
    if "trajectory" in doc:
        options += [(("trajectory",), "samples", "sample"), (("trajectory",), "t_end", "tend")]
    options = [o for o in options if o[1] in _get(doc, o[0])]
    where, old, new = rng.choice(options)
    table = _get(doc, where)
    table[new] = table.pop(old)
    return f"renamed {_path_text(where + (old,))} to {new}", doc, "invalid", "invalid"


def _wrong_type(doc, rng):
    j = rng.randrange(len(doc["joints"]))
    b = rng.randrange(len(doc["bodies"]))
    leaf = rng.choice(_numeric_leaves(doc))
    options = [
        (("joints", j, "type"), rng.choice([["R"], {"R": 1}, 1, True])),
        (("joints", j, "parent"), rng.choice(["0", Decimal("0.5"), True, [0]])),
        (("joints", j, "child"), rng.choice(["1", Decimal("1.5"), False, {"a": 1}])),
        (("bodies", b, "label"), rng.choice(["1", Decimal("1.0"), [1], True])),
        (("mechanism", "name"), rng.choice([5, ["x"], {"a": "b"}])),
        (("joints", j, "parent_frame"), rng.choice(["0", [0, 0, 0], 1])),
        (("joints", j, "child_frame", "point"), rng.choice(["0", ["0", "0"], [["0"], ["0"], ["0"]], {"x": "0"}])),
        (leaf, rng.choice([["1"], {"a": "1"}, True, ""])),
        (("bodies",), rng.choice(["rod", {"label": 1}])),
    ]
    if "trajectory" in doc:
        options.append((("trajectory", "samples"), rng.choice(["100", Decimal("100.5"), True, [100]])))
        options.append((("trajectory", "q"), rng.choice(["sin(t)", ["sin(t)"]])))
    path, value = rng.choice(options)
    _set(doc, path, value)
    return f"{_path_text(path)} = {_value(value)[:40]}", doc, "invalid", "invalid"


def _extreme_number(doc, rng):
    path = rng.choice(_numeric_leaves(doc))
    value = rng.choice(EXTREME)
    _set(doc, path, value)
    return f"{_path_text(path)} = {value[:24]}{'...' if len(value) > 24 else ''}", doc, "invalid", "invalid"


def _huge_but_parseable(doc, rng):
    path = rng.choice(_numeric_leaves(doc))
    value = rng.choice(HUGE_BUT_PARSEABLE)
    _set(doc, path, value)
    return f"{_path_text(path)} = {value}", doc, "any", "any"


def _absurd_samples(doc, rng):
    if "trajectory" not in doc:
        doc["trajectory"] = {"q": {}}
    value = rng.choice([1000000000, 10 ** 18, 0, -5, 1])
    doc["trajectory"]["samples"] = value
    return f"trajectory.samples = {value}", doc, "invalid", "invalid"


def _non_finite(doc, rng):
    path = rng.choice(_numeric_leaves(doc))
    value = rng.choice(NON_FINITE)
    _set(doc, path, value)
    return f"{_path_text(path)} = {_value(value)}", doc, "invalid", "invalid"


def _broken_reference(doc, rng):
    j = rng.randrange(len(doc["joints"]))
    options = [(("joints", j, "child"), 99), (("joints", j, "parent"), -1),
               (("coordinates",), {"independent": ["nope"]}),
               (("joints", j, "parent_frame", "point", 0), "Lx_unknown"),
               (("joints", j, "limits"), {"nope": ["-1", "1"]})]
    if "trajectory" in doc:
        options.append((("trajectory", "q", "nope"), "sin(t)"))
        options.append((("joints", j, "limits"), {c: ["t", "1"] for c in doc["joints"][j].get("coordinates", [])}
                        or {"nope": ["t", "1"]}))
    path, value = rng.choice(options)
    _set(doc, path, value)
    return f"{_path_text(path)} = {_value(value)}", doc, "invalid", "invalid"


def _cycle(doc, rng):
    j = rng.randrange(len(doc["joints"]))
    joint = doc["joints"][j]
    kind = rng.choice(["self", "duplicate"])
    if kind == "self":
        joint["parent"] = joint["child"]
        return f"joints[{j}] connects body {joint['child']} to itself", doc, "invalid", "invalid"
    twin = copy.deepcopy(joint)
    twin["name"] = str(joint.get("name", "J")) + "_twin"
    if "coordinates" in twin:
        twin["coordinates"] = [c + "_twin" for c in twin["coordinates"]]
    twin["loop"] = True
    doc["joints"].append(twin)
    return f"joints[{j}] duplicated (a redundant joint between the same bodies)", doc, "invalid", "invalid"


def _non_physical(doc, rng):
    bodies = [b for b, body in enumerate(doc["bodies"]) if "mass" in body]
    if not bodies:
        doc["geometry"] = dict(doc.get("geometry", {}), m1="1")
        return "geometry name m1 (a parameter name)", doc, "invalid", "invalid"
    b = rng.choice(bodies)
    kind = rng.choice(["mass", "inertia", "triangle", "collision"])
    if kind == "mass":
        doc["bodies"][b]["mass"] = "-1"
        return f"bodies[{b}].mass = -1", doc, "invalid", "invalid"
    if kind == "inertia":
        doc["bodies"][b]["inertia_com"][0] = "-0.5"
        return f"bodies[{b}].inertia_com[0] (Ixx) = -0.5", doc, "invalid", "invalid"
    if kind == "triangle":
        doc["bodies"][b]["inertia_com"] = ["1", "0", "0", "0.1", "0", "0.1"]
        return f"bodies[{b}].inertia_com breaks the triangle inequality", doc, "invalid", "invalid"
    doc["geometry"] = dict(doc.get("geometry", {}), m2="1")
    return "geometry name m2 (a parameter name)", doc, "invalid", "invalid"


def _huge_integer(doc, rng):
    """Integers past CPython's 4300-digit int() guard, or merely absurd, where integers go."""
    j = rng.randrange(len(doc["joints"]))
    b = rng.randrange(len(doc["bodies"]))
    value = rng.choice([RawInteger("9" * 5000), 10 ** 40, -(10 ** 30)])
    options = [("joints", j, "parent"), ("joints", j, "child"), ("bodies", b, "label")]
    if "trajectory" in doc:
        options.append(("trajectory", "samples"))
    path = rng.choice(options)
    _set(doc, path, value)
    shown = f"{len(value)}-digit integer" if isinstance(value, RawInteger) else str(value)
    return f"{_path_text(path)} = {shown}", doc, "invalid", "invalid"


RESERVED_NAMES = ["t", "pi", "sin", "E", "I", "lambda", "gamma", "nan", "Izz1", "m1", "mx2"]


def _name_collision(doc, rng):
    """A geometry or coordinate name that is a parameter name or means something else."""
    name = rng.choice(RESERVED_NAMES)
    j = rng.randrange(len(doc["joints"]))
    joint = doc["joints"][j]
    one_coordinate = joint["type"] in ("R", "P")
    if rng.random() < 0.5 or not one_coordinate:
        doc["geometry"] = dict(doc.get("geometry", {}), **{name: "1"})
        return f"geometry name {name}", doc, "invalid", "invalid"
    joint["coordinates"] = [name]
    return f"joints[{j}].coordinates = [{name!r}]", doc, "invalid", "invalid"


def _effect_mistake(doc, rng):
    """A broken [[effects]] table: unknown kind, coordinate or coefficient, a misspelt key,
    a wrong type, a duplicate."""
    coordinate = (doc.get("coordinates", {}).get("independent") or doc["joints"][0].get("coordinates")
                  or [doc["joints"][0].get("name", "J0_1")])[0]
    good = {"kind": "viscous_friction", "coordinate": coordinate}
    kind = rng.choice(["kind", "coordinate", "coefficient", "misspelt", "type", "duplicate", "not_array"])
    if kind == "kind":
        effects = [dict(good, kind="viscous_fiction")]
    elif kind == "coordinate":
        effects = [dict(good, coordinate="nope")]
    elif kind == "coefficient":
        effects = [dict(good, values={"fc": "0.5"})]
    elif kind == "misspelt":
        effects = [{"kind": "viscous_friction", "coordinat": coordinate}]
    elif kind == "type":
        effects = [dict(good, values=rng.choice([["0.5"], "0.5", {"fv": True}]))]
    elif kind == "duplicate":
        effects = [good, dict(good)]
    else:
        doc["effects"] = dict(good)
        return "effects is a table, not an array of tables", doc, "invalid", "invalid"
    doc["effects"] = effects
    return f"[[effects]] with a mistake ({kind})", doc, "invalid", "invalid"


def _unicode(doc, rng):
    kind = rng.choice(["title", "name", "geometry_key", "number", "key"])
    if kind == "title":
        doc["mechanism"]["title"] = "Pendule \u00fc \u4e2d\u6587 \U0001F680 \u202e"
        return "unicode title", doc, "valid", "valid"
    if kind == "name":
        doc["mechanism"]["name"] = "p\u00e9ndulo"
        return "unicode mechanism.name", doc, "invalid", "invalid"
    if kind == "geometry_key":
        doc["geometry"] = dict(doc.get("geometry", {}), **{"L\u00e9": "1"})
        return "geometry key L\u00e9", doc, "invalid", "invalid"
    if kind == "key":
        doc["bodies"][0]["m\u0430ss"] = "1"           # a Cyrillic a: looks like "mass"
        return "bodies[0] key with a Cyrillic letter", doc, "invalid", "invalid"
    path = rng.choice(_numeric_leaves(doc))
    value = rng.choice(JUNK_TEXT)
    _set(doc, path, value)
    return f"{_path_text(path)} = {value!r}", doc, "invalid", "invalid"


def _bom(text, rng):
    kind = rng.choice(["utf8", "utf8_twice", "utf16"])
    if kind == "utf8":
        return "UTF-8 BOM before the text", b"\xef\xbb\xbf" + text, "valid", "valid"
    if kind == "utf8_twice":
        return "two UTF-8 BOMs", b"\xef\xbb\xbf" * 2 + text, "invalid", "invalid"
    return "UTF-16 text with its BOM", text.decode("utf-8").encode("utf-16"), "invalid", "invalid"


def _binary_junk(text, rng):
    junk = bytes([0xff]) + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 16)))
    at = rng.randrange(len(text))
    return f"{len(junk)} junk bytes at byte {at}", text[:at] + junk + text[at:], "invalid", "invalid"


def _truncated(text, rng):
    at = rng.randrange(1, len(text) - 1)
    return f"truncated at byte {at} of {len(text)}", text[:at], "any", "any"


def _empty(text, rng):
    return "empty file", rng.choice([b"", b"\n", b"# nothing\n"]), "invalid", "invalid"


DOC_MUTATIONS = {
    "delete_required": _delete_required, "delete_trajectory": _delete_trajectory,
    "misspelt_key": _misspell_key, "wrong_type": _wrong_type, "extreme_number": _extreme_number,
    "huge_number": _huge_but_parseable, "absurd_samples": _absurd_samples, "non_finite": _non_finite,
    "broken_reference": _broken_reference, "cycle": _cycle, "non_physical": _non_physical,
    "unicode": _unicode, "huge_integer": _huge_integer, "name_collision": _name_collision,
    "effect_mistake": _effect_mistake,
}
BYTE_MUTATIONS = {"bom": _bom, "binary_junk": _binary_junk, "truncated": _truncated, "empty": _empty}
KINDS = ("identity",) + tuple(DOC_MUTATIONS) + tuple(BYTE_MUTATIONS)


def mechanism_files() -> dict:
    return {p.stem: p for p in sorted(MECHANISMS.glob("*.toml"))}


def corpus(seed: int = 0, per_kind: int = 1, mechanisms=None, kinds=KINDS) -> list:
    """Every mutation kind ``per_kind`` times on every built-in file (or those named), plus the
    unchanged file re-written by the TOML writer ("identity", valid: a check of the writer)."""
    cases = []
    for name, path in mechanism_files().items():
        if mechanisms is not None and name not in mechanisms:
            continue
        raw = path.read_bytes()
        doc = tomllib.loads(raw.decode("utf-8"), parse_float=Decimal)
        for kind in kinds:
            for n in range(1 if kind == "identity" else per_kind):
                rng = random.Random(zlib.crc32(f"{seed}:{name}:{kind}:{n}".encode()))
                if kind == "identity":
                    detail, data, show, solve = "unchanged, re-written", dumps(doc).encode(), "valid", "valid"
                elif kind in BYTE_MUTATIONS:
                    detail, data, show, solve = BYTE_MUTATIONS[kind](raw, rng)
                else:
                    detail, new, show, solve = DOC_MUTATIONS[kind](copy.deepcopy(doc), rng)
                    data = dumps(new).encode("utf-8", "surrogatepass")
                cases.append(Case(f"{name}.{kind}.{n}", name, kind, detail, data, show, solve))
    return cases


# ----- running one case ------------------------------------------------------------

COMMANDS = {"show": ["show"], "solve": ["solve", "--solver", "dp"]}


@dataclass
class Outcome:
    case: Case
    command: str
    returncode: int | None    # None: stopped at the CPU (or wall-clock) limit
    stderr: str
    seconds: float

    @property
    def verdict(self) -> str:
        """ok | hang | traceback | exit<N> | exit0_on_invalid | exit2_on_valid."""
        if self.returncode is None:
            return "hang"
        if "Traceback (most recent call last)" in self.stderr:
            return "traceback"
        if self.returncode not in (0, 2):
            return f"exit{self.returncode}"
        expect = self.case.expect(self.command)
        if expect == "invalid" and self.returncode == 0:
            return "exit0_on_invalid"
        if expect == "valid" and self.returncode == 2:
            return "exit2_on_valid"
        return "ok"

    @property
    def message(self) -> str:
        lines = [line for line in self.stderr.strip().splitlines() if line.strip()]
        return lines[-1] if lines else ""


WALL_FACTOR = 6       # wall-clock backstop = WALL_FACTOR x the CPU limit (a loaded machine is slow)


def run_case(case: Case, command: str, directory: Path, timeout: float = 20.0) -> Outcome:
    """Write the case's file and run ``baseparams <command>`` on it in a fresh interpreter.

    ``timeout`` limits the child's CPU time (RLIMIT_CPU), so that a busy machine does not
    turn slow runs into false hangs; the wall clock is only a backstop. A run stopped by
    either limit has ``returncode`` None.
    """
    path = Path(directory) / f"{case.name}.toml"
    path.write_bytes(case.data)
    argv = [sys.executable, "-m", "baseparams.cli", *COMMANDS[command][:1], str(path), *COMMANDS[command][1:]]
    seconds = max(1, math.ceil(timeout))

    def limit_cpu():
        resource.setrlimit(resource.RLIMIT_CPU, (seconds, seconds + 1))

    start = time.perf_counter()
    try:
        proc = subprocess.run(argv, capture_output=True, timeout=seconds * WALL_FACTOR, preexec_fn=limit_cpu)
    except subprocess.TimeoutExpired as exc:
        stderr = (exc.stderr or b"").decode("utf-8", "replace")
        return Outcome(case, command, None, stderr, time.perf_counter() - start)
    elapsed = time.perf_counter() - start
    stopped = proc.returncode in (-signal.SIGXCPU, -signal.SIGKILL)
    return Outcome(case, command, None if stopped else proc.returncode,
                   proc.stderr.decode("utf-8", "replace"), elapsed)


# ----- bad command-line values: solver options, output targets, scheduler addresses ---------
# (issue 24). Each is a full argument list for `baseparams` with what a correct program must
# do: "invalid" (exit 2, one `error:` line), "valid" (exit 0) or "any" (0 or 2); never a
# traceback, another exit code, or a result from a degenerate setting.

INT_VALUES = {"-1": "invalid", "1_0": "invalid", "\u0663": "invalid", "\uff11\uff10": "invalid",
              "nan": "invalid", "": "invalid", "true": "invalid", "9" * 50: "invalid", "1e3": "invalid",
              "2147483648000": "invalid", "0x10": "invalid", " 12 ": "any", "0": None}
INT_LIST_VALUES = {"": "invalid", "0": "invalid", "-5,30": "invalid", "30,10000000": "invalid",
                   "a,b": "invalid", "30,30": "invalid", "1_0,20": "invalid"}
BOOL_VALUES = {"maybe": "invalid", "2": "invalid", "": "invalid", "TRUE": "valid"}
CHOICE_VALUES = {"sideways": "invalid", "": "invalid", "NATURAL": "invalid"}
NAME_LIST_VALUES = {"zz": "invalid", "1": "invalid", "m1;Izz1": "invalid"}
OPTION_TYPES = {  # solver -> option -> kind (the declarations, written out: the corpus must
    "dp": {"samples": "int", "rank": "int", "seed": "seed", "scale": "bool", "pivoting": "choice"},
    "vp": {"digits": "int", "samples": "int", "seed": "seed", "ladder": "ints", "kept": "ints",
           "pivoting": "choice", "recover": "bool"},
    "exact": {"samples": "int", "seed": "seed"},
    "symbolic": {"digits": "int", "samples": "int", "seed": "seed", "keep": "names",
                 "eliminate_first": "names", "certify": "bool"},
}                 # not read them, or a wrong range would agree with itself)


@dataclass(frozen=True)
class CommandCase:
    name: str
    args: tuple
    expect: str               # "invalid" | "valid" | "any"


def option_cases(mechanism: str = "pendulum") -> list:
    """Every built-in solver's every option with values of the wrong form or range."""
    cases = []
    for solver, options in OPTION_TYPES.items():
        for option, kind in options.items():
            values = {"int": INT_VALUES, "seed": INT_VALUES, "ints": INT_LIST_VALUES, "bool": BOOL_VALUES,
                      "choice": CHOICE_VALUES, "names": NAME_LIST_VALUES}[kind]
            for k, (value, expect) in enumerate(values.items()):
                if expect is None:           # "0": a valid seed, below every other range
                    expect = "valid" if kind == "seed" else "invalid"
                # " 12 " (spaces trimmed): 12 digits or samples are fine, a rank of 12 on 10
                # parameters is not: "any" covers both; no traceback either way
                args = ("solve", mechanism, "--solver", solver, "-O", f"{option}={value}", "--format", "json")
                cases.append(CommandCase(f"option.{solver}.{option}.{k}", args, expect))
    cases += [
        CommandCase("option.dp.rank_above_rows", ("solve", mechanism, "--solver", "dp", "-O", "rank=3",
                                                  "-O", "samples=2"), "invalid"),
        CommandCase("option.vp.kept_too_few", ("solve", mechanism, "--solver", "vp", "-O", "kept=1",
                                               "-O", "ladder=30,60"), "invalid"),
        CommandCase("option.vp.kept_dependent", ("solve", mechanism, "--solver", "vp", "-O", "kept=0,1,2,3"),
                    "invalid"),
        CommandCase("option.digits_and_O", ("solve", mechanism, "--solver", "vp", "--digits", "30", "-O",
                                            "digits=40"), "invalid"),
    ]
    return cases


def output_cases(folder: str) -> list:
    """Output targets every writing verb must refuse cleanly (exit 2), or write."""
    writers = [("report", "pendulum", "--no-certify", "-o"), ("export", "pendulum", "--to", "python", "-o"),
               ("convert", "pendulum", "-o"), ("plot", "mechanism", "pendulum", "-o")]
    targets = {"empty": ("", "invalid"), "folder": (folder, "invalid"),
               "missing_folder": (f"{folder}/missing/out", "invalid"),
               "long_name": (f"{folder}/{'x' * 300}", "invalid"),
               "under_a_file": (f"{folder}/file.txt/out", "invalid"),
               "dev_full": ("/dev/full", "invalid")}
    cases = []
    for verb in writers:
        for label, (target, expect) in targets.items():
            suffix = {"convert": ".toml", "plot": ".png"}.get(verb[0], ".txt")
            path = target + suffix if target and label not in ("folder", "dev_full") else target
            if verb[0] == "convert" and label == "dev_full":
                path = target                # no suffix: "no writer" (exit 2) as well
            cases.append(CommandCase(f"output.{verb[0]}.{label}", (*verb, path), expect))
    return cases


SCHEDULER_ADDRESSES = ["not a url", "http://127.0.0.1:8786", "tcp://127.0.0.1", "tcp://127.0.0.1:0",
                       "tcp://127.0.0.1:99999", "tcp://:8786", "", "127.0.0.1", "tcp://a b:1", "\u0663:1"]


TIMEOUTS = ["nan", "inf", "-inf", "1e30", "-1", "0", "", "1_0", "\u0661"]


def scheduler_cases() -> list:
    """Addresses refused before any connection is tried (so no network is used), and
    --timeout values that are no number of seconds (issue 24: nan, inf, 1e30 exited 3)."""
    return ([CommandCase(f"scheduler.{k}", ("validate", "pendulum", "--scheduler", a, "--quiet"), "invalid")
             for k, a in enumerate(SCHEDULER_ADDRESSES)]
            + [CommandCase(f"timeout.{k}", ("validate", "pendulum", "--solvers", "dp", "--timeout", t, "--quiet"),
                           "invalid") for k, t in enumerate(TIMEOUTS)])

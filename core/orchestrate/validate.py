"""``validate``: every applicable solver on every mechanism, cross-checked, as one report.

Per mechanism, one job per solver plus one for the model checks
(:mod:`.model_checks`); the runner decides where they run. The report's JSON is the same
whichever runner ran it, timings apart.
"""

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from baseparams import registry
from baseparams.errors import InputError
from baseparams.io.loader import load_mechanism
from baseparams.orchestrate.checks import cross_checks
from baseparams.orchestrate.jobs import (MODEL, NOT_APPLICABLE, OK, Job, MechanismText, Outcome)
from baseparams.orchestrate.model_checks import Check
from baseparams.orchestrate.runners import InProcess, Progress, Runner


@dataclass
class MechanismReport:
    name: str
    source: str
    solvers: dict[str, dict[str, Any]] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "ok": self.ok, "source": self.source, "solvers": self.solvers,
                "checks": [c.to_json() for c in self.checks]}


@dataclass
class Report:
    mechanisms: list[MechanismReport]
    solvers: list[str]

    @property
    def ok(self) -> bool:
        return all(m.ok for m in self.mechanisms)

    def to_json(self) -> dict[str, Any]:
        return {"ok": self.ok, "solvers": list(self.solvers), "mechanisms": [m.to_json() for m in self.mechanisms]}


def mechanism_texts(names_or_paths: Iterable[str]) -> list[MechanismText]:
    """Registered names or file paths -> their files' text. Each file is read here first, so
    a bad one is an InputError (exit 2) naming file, key and reason, not a failed check; a
    worker that cannot read what this process can reports a missing plugin instead."""
    known = registry.mechanisms()
    out: list[MechanismText] = []
    for item in names_or_paths:
        if item in known:
            path, name = Path(known[item].item.path), item
        else:
            path = Path(item)
            if not path.is_file():
                raise InputError(f"unknown mechanism {item!r}: not a registered name "
                                 f"({', '.join(known) or 'none registered'}) and not a file")
            name = path.stem
        if any(m.name == name for m in out):           # two files of one name: keep both apart
            name = f"{name}#{len(out) + 1}"
        try:
            out.append(MechanismText.read(name, path))
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read: {exc}", file=path) from None
        load_mechanism(path)
    return out


def select_solvers(names: Sequence[str] | None) -> list[str]:
    known = registry.solvers()
    if not names:
        return list(known)
    unknown = [n for n in names if n not in known]
    if unknown:
        raise InputError(f"unknown solver(s) {', '.join(unknown)}; registered: {', '.join(known)}")
    return list(dict.fromkeys(names))


def validate(mechanisms: Sequence[MechanismText], solvers: Sequence[str] | None = None,
             runner: Runner | None = None, timeout: float | None = None,
             progress: Progress | None = None, model: bool = True) -> Report:
    """Run every solver (and the model checks) on every mechanism and cross-check them."""
    solvers = select_solvers(solvers)
    jobs = [Job(m, s) for m in mechanisms for s in ([MODEL] if model else []) + solvers]
    jobs.sort(key=expected_cost, reverse=True)     # longest first: workers finish together
    outcomes = (runner or InProcess()).run(jobs, timeout=timeout, progress=progress)
    capabilities = {n: getattr(r.item, "capabilities", None) for n, r in registry.solvers().items()}
    reports = []
    for m in mechanisms:
        mine = {o.solver: o for o in outcomes if o.mechanism == m.name}
        reports.append(_mechanism_report(m, mine, solvers, capabilities))
    return Report(reports, solvers)


SOLVER_WEIGHT = {"vp": 3.0, "symbolic": 2.0, MODEL: 1.5, "dp": 0.5, "exact": 0.3}


def expected_cost(job: Job) -> float:
    """A rough guess of a job's time, to start the longest first (the report's order does not
    depend on it): bodies x (1 + loops), read from a TOML file's tables (loops = joints -
    bodies), times a weight per solver; other formats by their text's length."""
    text = job.mechanism.text
    bodies, joints = text.count("[[bodies]]"), text.count("[[joints]]")
    size = bodies * (1 + max(0, joints - bodies)) if bodies else len(text) / 1000
    return size * SOLVER_WEIGHT.get(job.solver, 1.0)


def _mechanism_report(m: MechanismText, outcomes: dict[str, Outcome], solvers: Sequence[str],
                      capabilities: Mapping[str, Any]) -> MechanismReport:
    report = MechanismReport(m.name, m.source)
    model = outcomes.get(MODEL)
    if model is not None:
        if model.status == OK and model.result is not None:
            report.checks += [Check(c["name"], c["ok"], c["detail"]) for c in model.result["checks"]]
        else:
            report.checks.append(Check("model checks", False, f"{model.status}: {model.message}"))
    results: dict[str, dict[str, Any]] = {}
    for name in solvers:
        o = outcomes[name]
        row = {"status": o.status, "seconds": round(o.seconds, 3)}
        if o.status == OK and o.result is not None:
            row.update(rank=o.result["rank"], certified=bool(o.result.get("certified")),
                       warnings=len(o.result.get("warnings") or []))
            results[name] = o.result
        elif o.status == NOT_APPLICABLE:
            row["verdict"] = f"not applicable: {o.message}"
        else:
            row["verdict"] = f"{o.status.replace('_', ' ')}: {o.message}"
            report.checks.append(Check(f"{name} ran", False, f"{o.status.replace('_', ' ')}: {o.message}"))
        report.solvers[name] = row
    checks = cross_checks(results, capabilities)
    report.checks += checks
    for name in results:
        failed = [c for c in checks if not c.ok and c.about == name]
        warned = [c for c in checks if c.warned and c.about == name]
        report.solvers[name]["verdict"] = ("disagrees" if failed else
                                           "unreliable here, warned" if warned else "agrees")
    return report


# ----- rendering ------------------------------------------------------------------------------
def render_text(report: Report) -> str:
    lines = []
    width = max([len(m.name) for m in report.mechanisms] + [9])
    header = (f"{'mechanism':<{width}}  " + "  ".join(f"{s:<24}" for s in report.solvers)).rstrip()
    lines += [header, "-" * len(header)]
    for m in report.mechanisms:
        cells = [_cell(m.solvers[s]) for s in report.solvers]
        row = f"{m.name:<{width}}  " + "  ".join(f"{c:<24}" for c in cells)
        lines.append(row.rstrip() + ("" if m.ok else "  FAILED"))
    failed = [(m, c) for m in report.mechanisms for c in m.checks if not c.ok]
    warned = [(m, c) for m in report.mechanisms for c in m.checks if c.warned]
    notes = [(m.name, s, row["verdict"]) for m in report.mechanisms for s, row in m.solvers.items()
             if row["status"] == NOT_APPLICABLE]
    if notes:
        lines.append("")
        lines += [f"{name}: {s}: {verdict}" for name, s, verdict in notes]
    if warned:
        lines.append("")
        lines += [f"{m.name}: {c.name}: {c.detail}" for m, c in warned]
    if failed:
        lines.append("")
        lines.append("FAILED checks:")
        lines += [f"  {m.name}: {c.name}: {c.detail}" for m, c in failed]
    checks = sum(len(m.checks) for m in report.mechanisms)
    lines.append("")
    lines.append(f"{'all agree' if report.ok else 'DISAGREEMENT'}: {len(report.mechanisms)} mechanism(s), "
                 f"{len(report.solvers)} solver(s), {checks} checks, {len(failed)} failed")
    return "\n".join(lines)


def _cell(row: dict) -> str:
    if row["status"] == OK:
        verdict = {"agrees": "ok", "disagrees": "DISAGREES", "unreliable here, warned": "warned"}[row["verdict"]]
        return f"{row['rank']}{'*' if row['certified'] else ''} {row['seconds']:.1f}s {verdict}"
    if row["status"] == NOT_APPLICABLE:
        return "n/a"
    return row["status"].upper()


def render_markdown(report: Report) -> str:
    lines = ["| mechanism | " + " | ".join(report.solvers) + " | checks |",
             "|---|" + "---|" * len(report.solvers) + "---|"]
    for m in report.mechanisms:
        cells = [_cell(m.solvers[s]) for s in report.solvers]
        ok = sum(c.ok for c in m.checks)
        lines.append(f"| {m.name} | " + " | ".join(cells) + f" | {ok}/{len(m.checks)} |")
    lines.append("")
    lines.append("rank, * certified, seconds, verdict; n/a: the solver does not take this mechanism.")
    failed = [(m, c) for m in report.mechanisms for c in m.checks if not c.ok]
    if failed:
        lines += ["", "**Failed checks**", ""] + [f"- {m.name}: {c.name}: {c.detail}" for m, c in failed]
    return "\n".join(lines)

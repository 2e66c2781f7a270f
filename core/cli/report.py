"""Derivation reports of the symbolic solver, like the seed paper's Tabs. 4-5 and appendix.

One report, three renderings (``text``, ``markdown``, ``latex``):

1. parameters without effect: body, its motion, the paper's condition number, parameters
   (Tab. 4);
2. multipole transfers: donor -> acceptor, joint and type, conditions, multipoles and the
   parameters they eliminate (Tab. 5), then the generators that were redundant;
3. the derivation step by step (the appendix): for each transfer, the multipole's amount
   (chosen so that the eliminated parameter becomes zero) and the parameters it changes,
   as linear forms in the original parameters;
4. the base parameters, and how the rank was checked: what ball arithmetic proves
   (rank >= r) and what is numerical evidence (every generator n gives balls W n that
   contain 0 on the sampled states, hence rank <= the count, not proven).

Condition numbers are the paper's: section 3.2 (one body) and section 3.3 (a joint);
0 marks a transfer found by sampling the kinematics that no joint-type rule states.
"""

from typing import TYPE_CHECKING, Any

import sympy

from baseparams.model.params import split_name

if TYPE_CHECKING:
    from baseparams.solvers.result import BaseParameterResult

MULTIPOLE_SYMBOL = {"monopole": "m", "dipole": "d", "quadrupole": "q"}
FORMATS = ("text", "markdown", "latex")


def render(result: "BaseParameterResult", fmt: str = "text") -> str:
    """The derivation report of a result whose ``diagnostics.derivation`` is present."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown report format {fmt!r}; choose from {', '.join(FORMATS)}")
    der = result.diagnostics.derivation
    if der is None:
        raise ValueError("this result carries no derivation (only a solver whose capabilities "
                         "include one makes it: symbolic)")
    return _Writer(fmt, der, result).write()


class _Writer:
    def __init__(self, fmt: str, der: Any, result: "BaseParameterResult") -> None:
        self.fmt, self.der, self.result = fmt, der, result
        self.f = der.field
        self.order = {p: i for i, p in enumerate(der.mechanism.parameters)}
        self.lines: list[str] = []

    # ----- formatting primitives ---------------------------------------------------
    def param(self, name: str) -> str:
        if self.fmt != "latex":
            return name
        kind, key = split_name(name)          # key: a body label, or a named body's name (issue 45)
        sub = key if isinstance(key, int) else "\\mathrm{" + key.replace("_", "\\_") + "}"
        return f"\\mathit{{{kind}}}_{{{sub}}}"

    def expr(self, e: Any) -> str:
        e = sympy.factor(e) if not e.is_Number else e
        return sympy.latex(e) if self.fmt == "latex" else str(e)

    def form(self, form: Any, first: Any = None) -> str:
        """A linear form {parameter: field element} as text (``first`` printed first)."""
        terms = sorted(form.items(), key=lambda t: (t[0] != first, self.order[t[0]]))
        if not terms:
            return "0"
        out = ""
        for p, c in terms:
            c = sympy.factor(self.f.to_sympy(c))
            neg = c.could_extract_minus_sign()
            num, den = sympy.fraction(-c if neg else c)
            if self.fmt == "latex":
                top = self.param(p) if num == 1 else \
                    (f"\\left({sympy.latex(num)}\\right) " if num.is_Add else f"{sympy.latex(num)}\\,") + self.param(p)
                text = top if den == 1 else f"\\frac{{{top}}}{{{sympy.latex(den)}}}"
            else:
                top = p if num == 1 else (f"({num})" if num.is_Add else str(num)) + "*" + p
                text = top if den == 1 else top + "/" + (f"({den})" if den.is_Add or den.is_Mul else str(den))
            out += (" - " if neg else " + ") + text if out else ("-" if neg else "") + text
        return out

    def vector(self, v: Any) -> str:
        items = ", ".join(self.expr(sympy.sympify(c)) for c in v)
        return f"\\left({items}\\right)" if self.fmt == "latex" else f"({items})"

    def math(self, s: str) -> str:
        if self.fmt == "latex":
            return f"${s}$"
        if self.fmt == "markdown":
            return f"`{s}`"
        return s

    def heading(self, text: str, level: int = 1) -> None:
        if self.fmt == "markdown":
            self.lines += [f"{'#' * (level + 1)} {text}", ""]
        elif self.fmt == "latex":
            self.lines += [f"\\{'sub' * (level - 1)}section*{{{_tex_escape(text)}}}", ""]
        else:
            self.lines += [text, "-" * len(text)] if level == 1 else [text]

    def table(self, header: list[str], rows: list[list[str]]) -> None:
        if self.fmt == "markdown":
            self.lines.append("| " + " | ".join(header) + " |")
            self.lines.append("|" + "---|" * len(header))
            for r in rows:
                self.lines.append("| " + " | ".join(r) + " |")
        elif self.fmt == "latex":
            self.lines.append("\\begin{tabular}{|" + "l|" * len(header) + "}")
            self.lines.append("\\hline")
            self.lines.append(" & ".join(f"\\textbf{{{_tex_escape(h)}}}" for h in header) + " \\\\")
            self.lines.append("\\hline\\hline")
            for r in rows:
                self.lines.append(" & ".join(r) + " \\\\ \\hline")
            self.lines.append("\\end{tabular}")
        else:
            widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)]
            self.lines.append("  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip())
            for r in rows:
                self.lines.append("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip())
        self.lines.append("")

    def para(self, text: str) -> None:
        self.lines += [text, ""]

    def item(self, text: str) -> None:
        if self.fmt == "latex":
            self.lines.append(f"  \\item {text}")
        else:
            self.lines.append(f"- {text}")

    def begin_items(self) -> None:
        if self.fmt == "latex":
            self.lines.append("\\begin{itemize}")

    def end_items(self) -> None:
        if self.fmt == "latex":
            self.lines.append("\\end{itemize}")
        self.lines.append("")

    def plist(self, names: Any) -> str:
        return ", ".join(self.math(self.param(n)) for n in names) if self.fmt == "latex" else " ".join(names)

    # ----- sections ------------------------------------------------------------------
    def write(self) -> str:
        der, res = self.der, self.result
        mech = der.mechanism
        title = f"Symbolic base parameters of {mech.name} (multipole transfers)"
        if self.fmt == "markdown":
            self.lines += [f"# {title}", ""]
        elif self.fmt == "latex":
            self.lines += [f"\\section*{{{_tex_escape(title)}}}", ""]
        else:
            self.lines += [title, "=" * len(title), ""]
        n = len(mech.parameters)
        nc = len(der.conditions)
        nt = len(der.transfers)
        self.para(f"{n} inertial parameters; {nc} without effect on the dynamics, {nt} eliminated by "
                  f"multipole transfers: {n} - {nc} - {nt} = {res.rank} base parameters"
                  + f" ({status(res)}).")
        self.no_effect()
        self.transfers()
        self.steps()
        self.base()
        self.check()
        return "\n".join(self.lines).rstrip() + "\n"

    def no_effect(self) -> None:
        self.heading("1. Parameters without effect on the dynamics (cf. the paper's Tab. 4)")
        rows = []
        motions = {m.label: m for m in self.der.bodies}
        groups: dict[Any, Any] = {}
        for s in self.der.conditions:
            g = s.generator
            groups.setdefault((g.bodies[0], g.condition), []).append(s.pivot)
        for (body, cond), params in groups.items():
            rows.append([str(body), _tex_escape(motions[body].motion) if self.fmt == "latex" else motions[body].motion,
                         str(cond), self.plist(params)])
        if rows:
            self.table(["Body", "Motion", "Condition", "Parameters"], rows)
        else:
            self.para("None.")
        quiet = [str(m.label) for m in self.der.bodies if not any(s.generator.bodies[0] == m.label
                                                                 for s in self.der.conditions)]
        if quiet:
            self.para(f"Bodies {', '.join(quiet)}: no condition applies.")

    def transfers(self) -> None:
        self.heading("2. Multipole transfers (cf. the paper's Tab. 5)")
        groups: dict[Any, Any] = {}
        for s in self.der.transfers:
            g = s.generator
            key = (g.joint_name, g.donor, g.acceptor)
            grp = groups.setdefault(key, {"type": g.joint_type, "conds": [], "poles": [], "params": []})
            if g.condition not in grp["conds"]:
                grp["conds"].append(g.condition)
            pole = "all q" if g.label.startswith("quadrupole ") and g.multipole == "quadrupole" else \
                MULTIPOLE_SYMBOL[g.multipole]
            if pole not in grp["poles"]:
                grp["poles"].append(pole)
            grp["params"].append(s.pivot)
        rows = []
        for (joint, donor, acceptor), grp in groups.items():
            arrow = " $\\to$ " if self.fmt == "latex" else " -> "
            poles = ", ".join(("all " + self.math(p[-1]) if p.startswith("all") else self.math(p))
                              if self.fmt == "latex" else p for p in grp["poles"])
            rows.append([f"{donor}{arrow}{acceptor}", _tex_escape(joint) if self.fmt == "latex" else joint,
                         grp["type"], ",".join(str(c) for c in grp["conds"]), poles, self.plist(grp["params"])])
        if rows:
            self.table(["Bodies (donor -> acceptor)" if self.fmt != "latex" else "Bodies",
                        "Joint", "Type", "Condition", "Multipole", "Eliminated"], rows)
        else:
            self.para("None.")
        if self.der.redundant:
            self.para("Redundant generators (already implied):")
            self.begin_items()
            for g, reason in self.der.redundant:
                where = f"joint {g.joint_name} ({g.joint_type})" if g.kind == "transfer" else f"body {g.bodies[0]}"
                text = f"{where}: {g.label}, condition {g.condition}: {reason}"
                self.item(_tex_escape(text) if self.fmt == "latex" else text)
            self.end_items()
        if self.der.missing_rules:
            names = ", ".join(f"{j.name} ({j.type.name})" for j in self.der.missing_rules)
            self.para(f"Joints whose type has no transfer rules: {names}.")

    def steps(self) -> None:
        self.heading("3. Derivation")
        self.para("Each step moves one multipole; its amount is chosen so that the eliminated "
                  "parameter becomes zero. Values are given in the original parameters, "
                  "after the step (a prime marks a changed parameter).")
        self.begin_items()
        for k, s in enumerate(self.der.steps, start=1):
            g = s.generator
            if g.kind == "condition":
                side = g.sides.get(g.bodies[0], {})
                where = ""
                if "point" in side and " at " not in g.label:
                    where = f" at {self.math(self.vector(side['point']))}"
                head = (f"Body {g.bodies[0]}, condition {g.condition}: {g.label}{where} has no effect; "
                        f"{self.math(self.param(s.pivot))} is removed.")
            elif len(g.bodies) > 2:        # a loop's generator: spread over its bodies, not moved
                head = (f"Loop closed by joint {g.joint_name} ({g.joint_type}), condition {g.condition}: "
                        f"{g.label}, spread over its bodies, has no effect; "
                        f"{self.math(self.param(s.pivot))} is removed.")
            else:
                donor, acceptor = g.donor, g.acceptor
                at = []
                for b in (donor, acceptor):
                    side = g.sides.get(b)
                    if side and b != 0:
                        at.append(f"{self.math(self.vector(side['point']))} in body {b}")
                where = f" at {' and '.join(at)}" if at else ""
                cond = "found by sampling" if g.condition == 0 else f"condition {g.condition}"
                head = (f"Joint {g.joint_name} ({g.joint_type}), {cond}: {g.label} moved from body "
                        f"{donor} to body {acceptor}{where}, eliminating {self.math(self.param(s.pivot))}.")
            if self.fmt == "latex":
                head = _tex_text(head)
            self.item(head)
            amount = self.form(_acceptor_amount(s))
            sym = MULTIPOLE_SYMBOL[g.multipole]
            details = [f"{sym} = {amount}"]
            for p in sorted(s.changes, key=lambda name: self.order[name]):
                details.append(f"{self.param(p)}' = {self.form(s.changes[p])}" if p != s.pivot
                               else f"{self.param(p)}' = 0")
            for d in details:
                if self.fmt == "latex":
                    self.lines.append(f"    \\\\ ${d}$")
                elif self.fmt == "markdown":
                    self.lines.append(f"  - `{d}`")
                else:
                    self.lines.append(f"    {d}")
        self.end_items()

    def base(self) -> None:
        self.heading("4. Base parameters")
        self.begin_items() if self.fmt == "latex" else None
        for k, (kept, form) in enumerate(self.der.base.items(), start=1):
            text = f"phi_b{k:02d} = {self.form(form, kept)}"
            if self.fmt == "latex":
                self.item(f"$\\phi_{{b,{k:02d}}} = {self.form(form, kept)}$")
            elif self.fmt == "markdown":
                self.lines.append(f"- `{text}`")
            else:
                self.lines.append(f"  {text}")
        self.end_items() if self.fmt == "latex" else self.lines.append("")

    def check(self) -> None:
        self.heading("5. Rank check")
        res = self.result
        self.para(_tex_escape(check_text(res)) if self.fmt == "latex" else check_text(res))
        for w in res.warnings:
            self.para(("Warning: " + _tex_escape(w)) if self.fmt == "latex" else f"Warning: {w}")


def status(result: "BaseParameterResult") -> str:
    """How the count stands, in a few words (the report's first paragraph)."""
    cert = result.diagnostics.details.get("certificate")
    if result.certified:
        return "certified"
    if result.rank_is_upper_bound:
        return "an upper bound: not certified"
    if not cert:
        return "not checked"
    if cert.get("generators_failed"):
        return "not certified: a generator failed its null-vector check"
    if cert.get("generators_untested"):
        return "not certified: some generators were not tested"
    return "not certified"


def check_text(result: "BaseParameterResult") -> str:
    """What the rank check proved, and what it only gives evidence for (section 5)."""
    cert = result.diagnostics.details.get("certificate")
    n = len(result.parameters)
    if not cert:
        return ("No numeric check was made. The count rests on the generators alone (joint-type rules, "
                "and body conditions accepted on sampled numerical evidence); nothing bounds the rank "
                "from below.")
    drawn = cert.get("random_states")
    states = (f"{cert['samples']} states ({drawn} drawn at random, {cert['samples'] - drawn} of the trajectory; "
              f"{cert['rows']} rows)" if drawn else f"{cert['samples']} states ({cert['rows']} rows)")
    text = (f"W was computed in ball arithmetic at {cert['digits']} digits on {states}. "
            f"Proven: rank >= {cert['rank_lower_bound']}")
    text += (" (the kept columns are independent). " if cert["kept_columns_proven"] else
             " (the shared ball analysis's rank; the kept columns themselves are not proven independent). ")
    total, passed = cert["generators"], cert["generators_passed"]
    if total and passed == total:
        text += (f"Each of the {total} generators n gives balls W n that all contain 0 (|W n| <= "
                 f"{cert['generator_residual']} max|W| max|n|): numerical evidence, not a proof, that "
                 f"rank <= {n} - {total} = {n - total} (a proof would need the generators verified "
                 f"symbolically).")
    elif total:
        text += f"{passed} of the {total} generators give balls W n that all contain 0"
        if cert["generators_failed"]:
            text += "; failed: " + "; ".join(f"{g['source']} (relative residual {g['residual']})"
                                              for g in cert["generators_failed"])
        if cert["generators_untested"]:
            text += "; not tested: " + "; ".join(g["source"] for g in cert["generators_untested"])
        text += "."
    if result.certified:
        text += " The proven lower bound meets the count: the rank is certified."
    elif result.rank_is_upper_bound:
        text += (" The count is only an upper bound: either the rules and conditions miss a dependency,"
                 " or the ball arithmetic could not prove that many independent columns (more digits"
                 " may).")
    else:
        text += " The rank is not certified."
    return text


def _acceptor_amount(step: Any) -> Any:
    """The step's multipole amount as the acceptor gains it (a condition: as the body gains it).

    Transfer generators are (parent's change) - (child's change), so an acceptor that is the
    child gains minus the step's coefficient."""
    g = step.generator
    if g.kind == "transfer" and g.joint is not None and g.acceptor == g.joint.child:
        return {p: -c for p, c in step.amount.items()}
    return step.amount


def _tex_escape(text: str) -> str:
    return (str(text).replace("\\", "\\textbackslash{}").replace("_", "\\_").replace("&", "\\&")
            .replace("%", "\\%").replace("#", "\\#"))


def _tex_text(text: str) -> str:
    """Escape text outside $...$ math spans."""
    parts = text.split("$")
    return "$".join(_tex_escape(p) if i % 2 == 0 else p for i, p in enumerate(parts))

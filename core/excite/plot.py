"""The plan as a figure: the motion (q, qd, qdd per coordinate against its limits) and the
singular values of the scaled observation matrix before and after (matplotlib, lazily)."""

from pathlib import Path

import numpy as np

from baseparams.excite.plan import FINER, Plan


def plot_plan(plan: Plan, path: str | Path, fmt: str | None = None) -> Path:
    """Draw ``plan`` (motion against its limits, singular values) to ``path``; the path written."""
    from baseparams.io.figures import new_figure as _figure, save_figure as _save
    p = plan.problem
    lim = p.limits
    t = p.times(FINER)
    q, qd, qdd = p.form.motion(plan.x, t)
    fig = _figure(figsize=(13, 7))
    titles = (("position", q, None), ("velocity", qd, lim.velocity), ("acceleration", qdd, lim.acceleration))
    for k, (title, values, bound) in enumerate(titles):
        ax = fig.add_subplot(2, 2, k + 1)
        for j, name in enumerate(p.form.names):
            line, = ax.plot(t, values[:, j], lw=0.9, label=name)
            lo, hi = (lim.lower[j], lim.upper[j]) if bound is None else (-bound[j], bound[j])
            if np.isfinite(lo) and np.isfinite(hi):          # no acceleration limit given: no line
                ax.axhline(lo, color=line.get_color(), lw=0.5, ls=":")
                ax.axhline(hi, color=line.get_color(), lw=0.5, ls=":")
        ax.set_title(f"{title} (dotted: limits)", fontsize=9)
        ax.set_xlabel("t (s)", fontsize=8)
        ax.tick_params(labelsize=7)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
    ax = fig.add_subplot(2, 2, 4)
    for label, check in (("before", plan.before), ("after", plan.after), ("random states", plan.random_states)):
        if check is not None and len(check.singular_values):
            s = np.asarray(check.singular_values)
            ax.semilogy(np.arange(1, len(s) + 1), s, marker=".", lw=0.8,
                        label=f"{label} (cond {check.condition:.3g})")
    ax.set_title("singular values of the scaled observation matrix", fontsize=9)
    ax.set_xlabel("index", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7)
    fig.suptitle(f"{plan.mechanism}: planned motion ({p.kind})", fontsize=10)
    fig.tight_layout()
    return _save(fig, path, fmt)

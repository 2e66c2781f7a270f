"""Helpers for solver authors: base-parameter rows in the result's layout, progress
messages, and the warnings every Gautier-type solver words the same way."""


def base_rows(parameters, kept, eliminated, coefficient):
    """[{"name": "phi_b01", "expression": {kept: "1", eliminated: coeff, ...}}] in kept order.

    ``coefficient(a, b)``: the string for row a (kept[a]) and column b (eliminated[b]), or
    None for a zero coefficient.
    """
    rows = []
    width = max(2, len(str(len(kept))))
    for a, i in enumerate(kept):
        expression = {parameters[i]: "1"}
        for b, j in enumerate(eliminated):
            text = coefficient(a, b)
            if text is not None:
                expression[parameters[j]] = text
        rows.append({"name": f"phi_b{a + 1:0{width}d}", "expression": expression})
    return rows


def say(progress, message):
    if progress:
        progress(message)


def untrusted_warning(items):
    return (f"{len(items)} nonzero coefficients have no trusted digit: omitted from the base "
            f"parameter expressions and listed in diagnostics.untrusted")


def raised_warning(mechanism, before, after, states, double_precision=False):
    cause = (f"the trajectory does not excite {mechanism.name}, or double precision lost a small "
             f"singular value of W" if double_precision else f"the trajectory does not excite {mechanism.name}")
    return (f"{cause}: rank raised from {before} to {after} by an independent random batch ({states} "
            f"random positions, velocities and accelerations), analysed together with W; use more "
            f"samples or a richer trajectory" + (", or vp" if double_precision else ""))

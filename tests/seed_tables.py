"""Tables of the seed paper (Iriarte et al.), transcribed for tests.

``SYMBOLIC_BASE``: the paper's Tab. 'Symbolic Base Inertial Parameters of the SLA
suspension' (label tab::tabla_parametros_base, 41 rows), one sympy-parsable string per
row, in the geometry symbols D12 D13 D22 D31 L7 L10 DKx DKy DKz and the inertial
parameter names m1 ... Izz7. Transcribed term by term from the LaTeX of the seed file
(/work/shared/seed/000_972a4153169b11e5.txt, lines ~620-690); rows 09 and 12 are the
uncommented versions (the commented-out drafts above them are the same expressions
before the paper factored m7 (1 - D13^2/(D12+D13)^2)).

``NO_EFFECT`` (Tab. 4, tab::eliminated_parameters) and ``TRANSFERS`` (Tab. 5,
tab::transferred_parameters): the conditions and transfers the paper applied by hand.
"""

import sympy

from baseparams.model.params import parameter_names

GEOMETRY_SYMBOLS = ("D12", "D13", "D22", "D31", "L7", "L10", "DKx", "DKy", "DKz")

SYMBOLIC_BASE = [
    "mx1 - m7*D13 + (Iyy1 + m7*D13**2)/(D12 + D13)",                                  # 01
    "mz1",                                                                             # 02
    "mx2 + Iyy2/D22",                                                                  # 03
    "mz2",                                                                             # 04
    "m3 + m1 + m7*(1 - D13**2/(D12 + D13)**2) - Iyy1/(D12 + D13)**2 + m2 - Iyy2/D22**2"
    " + m4 - Iyy4/L10**2 + m5",                                                        # 05
    "mx3 + m5*DKx + (m4 - Iyy4/L10**2)*D31",                                           # 06
    "my3 + m5*DKy - mx5",                                                              # 07
    "mz3 + m5*(DKz + L7/2) + (m2 - Iyy2/D22**2 - m1)*L7/2"
    " - m7*(1 - D13**2/(D12 + D13)**2)*L7/2 + Iyy1/(D12 + D13)**2*L7/2",               # 08
    "Ixx3 + (m2 - Iyy2/D22**2 + m1 + m7*(1 - D13**2/(D12 + D13)**2)"
    " - Iyy1/(D12 + D13)**2)*(L7/2)**2"
    " + Izz5 + m5*(DKy**2 + (DKz + L7/2)**2) - 2*DKy*mx5",                             # 09
    "Ixy3 - DKx*DKy*m5 + DKx*mx5",                                                     # 10
    "Ixz3 - DKx*(DKz + L7/2)*m5",                                                      # 11
    "Iyy3 + (m2 - Iyy2/D22**2 + m1 + m7*(1 - D13**2/(D12 + D13)**2)"
    " - Iyy1/(D12 + D13)**2)*(L7/2)**2"
    " + (m4 - Iyy4/L10**2)*D31**2 + (DKx**2 + (DKz + L7/2)**2)*m5",                    # 12
    "Iyz3 - m5*DKy*(DKz + L7/2) + (DKz + L7/2)*mx5",                                   # 13
    "Izz3 + Izz5 + m5*(DKx**2 + DKy**2) + (m4 - Iyy4/L10**2)*D31**2 - 2*DKy*mx5",      # 14
    "mx4 - Iyy4/L10",                                                                  # 15
    "my4",                                                                             # 16
    "mz4",                                                                             # 17
    "Ixx4",                                                                            # 18
    "Ixy4",                                                                            # 19
    "Ixz4",                                                                            # 20
    "Iyz4",                                                                            # 21
    "Izz4 - Iyy4",                                                                     # 22
    "my5",                                                                             # 23
    "mz5",                                                                             # 24
    "Ixx5",                                                                            # 25
    "Ixy5",                                                                            # 26
    "Ixz5",                                                                            # 27
    "Iyy5 - Izz5",                                                                     # 28
    "Iyz5",                                                                            # 29
    "mx6",                                                                             # 30
    "my6",                                                                             # 31
    "mz6",                                                                             # 32
    "Ixx6 + Ixx7",                                                                     # 33
    "Ixy6 + Ixy7",                                                                     # 34
    "Ixz6 + Ixz7",                                                                     # 35
    "Iyy6 + Iyy7",                                                                     # 36
    "Iyz6 + Iyz7",                                                                     # 37
    "Izz6 + Izz7",                                                                     # 38
    "mx7",                                                                             # 39
    "my7",                                                                             # 40
    "mz7",                                                                             # 41
]

# Tab. 4: body -> {condition: parameters that do not appear in the equations of motion}
NO_EFFECT = {
    1: {2: ["my1"], 5: ["Ixx1", "Ixy1", "Ixz1", "Iyz1", "Izz1"]},
    2: {2: ["my2"], 5: ["Ixx2", "Ixy2", "Ixz2", "Iyz2", "Izz2"]},
    6: {1: ["m6"]},
}

# Tab. 5: (bodies, joint type, conditions, eliminated parameters), in the paper's order
TRANSFERS = [
    ((1, 7), "S", (1,), ["m7"]),
    ((0, 1), "R", (1,), ["Iyy1"]),
    ((0, 2), "R", (1,), ["Iyy2"]),
    ((0, 4), "U", (1,), ["Iyy4"]),
    ((1, 3), "S", (1,), ["m1"]),
    ((2, 3), "S", (1,), ["m2"]),
    ((5, 3), "R", (1, 2, 5), ["m5", "mx5", "Izz5"]),
    ((4, 3), "S", (1,), ["m4"]),
    ((6, 7), "P", (6,), ["Ixx7", "Ixy7", "Ixz7", "Iyy7", "Iyz7", "Izz7"]),
]

SLA_PARAMETERS = parameter_names(range(1, 8))


def symbolic_base_matrix(geometry=None):
    """The paper's 41 rows as coefficient lists over the 70 parameters.

    ``geometry``: {symbol name: Fraction}; given, the coefficients are exact Fractions
    (geometry substituted), else sympy expressions in the geometry symbols.
    """
    from fractions import Fraction

    params = [sympy.Symbol(p) for p in SLA_PARAMETERS]
    local = {name: sympy.Symbol(name) for name in GEOMETRY_SYMBOLS + tuple(SLA_PARAMETERS)}
    subs = {}
    if geometry:
        subs = {sympy.Symbol(k): sympy.Rational(v.numerator, v.denominator) for k, v in geometry.items()}
    rows = []
    for text in SYMBOLIC_BASE:
        expr = sympy.expand(sympy.sympify(text, locals=local))
        row = []
        for p in params:
            c = sympy.cancel(expr.coeff(p))
            if geometry:
                c = sympy.simplify(c.subs(subs))
                row.append(Fraction(int(c.p), int(c.q)))
            else:
                row.append(c)
        rows.append(row)
    return rows

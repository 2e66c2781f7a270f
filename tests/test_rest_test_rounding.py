"""changesearch.rest_test counts the directions its candidates add beyond the model against
the columns before the projection (issue 42): a candidate column inside the model is left as
rounding, which cut against itself counted as a direction in some runs and not in others (df
55 to 57 on the PUMA for relative changes of 1e-15 in the columns)."""

import numpy as np

from baseparams.diagnose.changesearch import rest_test


def test_columns_inside_the_model_add_no_direction_whatever_the_rounding():
    rng = np.random.default_rng(3)
    n, f, p = 400, 3, 5
    model = rng.standard_normal((n, f, p))
    inside = model @ rng.standard_normal((p, 6))                 # six columns the model spans
    outside = rng.standard_normal((n, f, 2))                     # two it does not
    columns = np.concatenate([inside, outside], axis=-1)
    residual = rng.standard_normal((n, f))
    weights = np.ones(f)
    first = rest_test(residual, columns, model, weights)
    assert first["df"] == 2
    for seed in range(5):                                        # rounding-sized changes of the columns
        wobble = 1 + 1e-15 * np.random.default_rng(seed).standard_normal(columns.shape)
        again = rest_test(residual, columns * wobble, model, weights)
        assert again["df"] == 2
        assert abs(again["stat"] - first["stat"]) <= 1e-9 * abs(first["stat"])

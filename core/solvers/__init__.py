"""What every solver shares: the result type, comparisons between results, and helpers
for solver authors. The solvers themselves are plugins (``baseparams.plugins.solvers``)."""

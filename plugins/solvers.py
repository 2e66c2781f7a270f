"""Built-in solvers plugin (registered through the baseparams entry points)."""

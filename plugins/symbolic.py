"""Built-in symbolic plugin (registered through the baseparams entry points)."""

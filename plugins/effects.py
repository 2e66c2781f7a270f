"""Built-in effects plugin (registered through the baseparams entry points)."""

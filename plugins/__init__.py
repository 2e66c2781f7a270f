"""Built-in plugins of baseparams, registered through the ``baseparams`` entry points."""

"""Reading logs into measured data: the one room every reader lives in.

- :mod:`.recording`: recording descriptions (TOML) mapping raw logs onto the model;
- :mod:`.data`: the project's CSV layout, :class:`MeasuredData`, filters and derivatives;
- :mod:`.tables`: a description's text logs (a header row, ``names`` for none, ``stacked`` for one value a line);
- :mod:`.bags`: ROS 1 and ROS 2 bags as tables, a topic each on its own clock (the ``ros`` extra);
- :mod:`.clocks`: a run's tables on one clock (time, rows and window, files on their own clocks, gaps);
- :mod:`.values`: a description's numbers (decimals exact, expressions);
- :mod:`.implied`: the description a CSV in the project's layout implies (irregular stamps: one pipeline);
- :mod:`.arrays`: ``.npz`` and ``.mat`` logs as named columns;
- :mod:`.simulate`: synthetic measured data with a known truth (the proof bench).

Imports only the layers below it (model, dynamics, io, numeric), never identify or diagnose.
"""
from baseparams.lazy import public_names

# public name -> its module, imported on first use
_PUBLIC = {
    "MeasuredData": "data",
    "read_measured": "data",
    "write_measured": "data",
    "concatenate": "data",
    "read_recording": "recording",
    "read_data": "recording",
    "read_description": "recording",
    "is_description": "recording",
    "simulate": "simulate",
    "simulate_change": "simulate",
}
__all__ = sorted(_PUBLIC)

__getattr__ = public_names(__name__, _PUBLIC)

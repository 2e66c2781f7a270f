"""Reading logs into measured data: the one room every reader lives in.

- :mod:`.description`: recording descriptions (TOML) mapping raw logs onto the model, read and checked;
- :mod:`.recording`: a description's runs read into measured data (channels mapped, samples checked);
- :mod:`.filtering`: a run's uniform piece low-passed, differentiated, torques and columns filtered alike;
- :mod:`.data`: :class:`MeasuredData` and its segments; the project's CSV layout read and written;
- :mod:`.delimited`: delimited text logs as named columns of numbers, within the memory budget;
- :mod:`.smoothing`: the positions' bandwidth and Savitzky-Golay differentiation;
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
    "read_description": "description",
    "is_description": "description",
    "simulate": "simulate",
    "simulate_change": "simulate",
}
__all__ = sorted(_PUBLIC)

__getattr__ = public_names(__name__, _PUBLIC)

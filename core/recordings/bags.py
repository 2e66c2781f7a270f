"""ROS bags as tables of named columns, read with the ``rosbags`` library (no ROS install).

ROS 1 (``.bag``) and ROS 2 (``.db3``, ``.mcap``, or a bag's folder with its
``metadata.yaml``) are read alike. A column is a topic and a field path:

- ``/joint_states.position[shoulder_pan_joint]``: a ``sensor_msgs/JointState`` field by
  joint name (looked up in the message's own ``name`` list, message by message, so a
  publisher that orders its joints differently is still read right);
- ``/wrench.wrench.force.z``, ``/currents.data[3]``: any numeric field by its path, a
  sequence by its index counted from 0.

Each topic is a table on its own clock: the description's ``time`` (``header.stamp``, the
message's stamp, by default; ``log_time``: when the recorder received it), in seconds from
the bag's first stamp of the topics used, counted in integer nanoseconds first so that no
sample's step is rounded. Several topics are several files on their own clocks, read on the
clock of the topic of the first torque channel as files are (docs/identification.md).

Why: ROS is where most robot logs are written, and a bag could not be read (issue 44).
"""

import re
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baseparams.errors import InputError

SUFFIXES = (".bag", ".db3", ".mcap")
STAMP = "header.stamp"        # the default clock: the messages' own stamps
LOG_TIME = "log_time"         # the recorder's clock: when each message was written
STEP = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[[^\]]+\])*)")
INSTALL = "pip install 'baseparams[ros]' (the rosbags library: no ROS installation needed)"


def is_bag(path: str | Path) -> bool:
    """A ROS bag: a ``.bag``, ``.db3`` or ``.mcap`` file, or a folder with a ROS 2 bag's
    ``metadata.yaml``."""
    path = Path(path)
    return path.suffix.lower() in SUFFIXES or (path.is_dir() and (path / "metadata.yaml").is_file())


@dataclass(frozen=True)
class Field:
    """A column of a bag: its topic and the steps into a message (attribute names, sequence
    indices, joint names)."""
    column: str
    topic: str
    steps: tuple[tuple[str, str | int], ...]


def _reader(path: Path) -> Any:
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InputError(f"a ROS bag is read with the rosbags library, which is not installed: {INSTALL}",
                         file=str(path)) from None
    ros1 = path.suffix.lower() == ".bag"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    return AnyReader([path], default_typestore=store)


def _refusals() -> tuple[type[BaseException], ...]:
    """The errors rosbags raises on a damaged or foreign file or message (input, not a bug)."""
    import struct

    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as ReaderError1
    from rosbags.rosbag2 import ReaderError as ReaderError2
    from rosbags.serde import SerdeError
    from rosbags.typesys import TypesysError
    return (AnyReaderError, ReaderError1, ReaderError2, SerdeError, TypesysError, OSError, ValueError, KeyError,
            IndexError, struct.error, UnicodeDecodeError)


def parse_field(column: str, topics: Collection[str]) -> Field | None:
    """The column's topic (the longest one that starts it, followed by ``.``) and steps; None
    when no topic of the bag starts it (the column may be another file's)."""
    owners = [t for t in topics if column.startswith(t.rstrip("/") + ".")]
    if not owners:
        return None
    topic = max(owners, key=len)
    path = column[len(topic.rstrip("/")) + 1:]
    steps: list[tuple[str, str | int]] = []
    for part in path.split("."):
        match = STEP.fullmatch(part)
        if not match:
            raise InputError(f"{path!r} is not a field path (names, and [index] or [joint name] after a sequence)",
                             key=f"column {column}")
        steps.append(("attr", match.group(1)))
        for index in re.findall(r"\[([^\]]+)\]", match.group(2)):
            index = index.strip().strip("'\"")
            steps.append(("index", int(index)) if re.fullmatch(r"-?\d+", index) else ("joint", index))
    return Field(column, topic, tuple(steps))


def _value(message: Any, field: Field, names: dict) -> float:
    """The field's value in one message (NaN where a joint is not in this message's names);
    ``names``: a cache of joint-name lists to their index."""
    value, parent = message, message
    for kind, step in field.steps:
        if kind == "attr":
            if not hasattr(value, str(step)):
                raise KeyError(step)
            parent, value = value, getattr(value, str(step))
        elif kind == "index":
            value = value[int(step)]
        else:                           # a joint's name: its place in the message's own list
            listed = _joint_names(parent, message)
            if listed is None:
                raise KeyError(f"[{step}]")
            key = tuple(listed)
            index = names.get(key)
            if index is None:
                index = names[key] = {n: k for k, n in enumerate(key)}
            if step not in index:
                return float("nan")
            value = value[index[step]]
    if hasattr(value, "sec") and hasattr(value, "nanosec"):           # a stamp: seconds
        return float(value.sec) + 1e-9 * float(value.nanosec)
    return float(value)


def _joint_names(parent: Any, message: Any) -> Any:
    """The joint names a ``[joint]`` index looks up: the enclosing message's ``name`` (a
    JointState) or ``joint_names``, else the whole message's (a controller state's
    ``actual.positions[joint]``: its ``joint_names`` are at the top); None when none."""
    for owner in (parent, message):
        for attribute in ("name", "joint_names"):
            listed = getattr(owner, attribute, None)
            if isinstance(listed, (list, tuple)):
                return listed
    return None


def _stamp_ns(message: Any, clock: str, received: int, topic: str, msgtype: str, path: Path) -> int:
    """The sample's time in integer nanoseconds: the recorder's (``log_time``) or a stamp field."""
    if clock == LOG_TIME:
        return int(received)
    value = message
    for part in clock.split("."):
        if not hasattr(value, part):
            raise InputError(f"topic {topic} ({msgtype}) has no field {clock!r} for its time: its messages carry no "
                             f"such stamp; time = \"{LOG_TIME}\" in [recording] reads every topic on the recorder's "
                             "clock", file=str(path), key="recording.time")
        value = getattr(value, part)
    if hasattr(value, "sec") and hasattr(value, "nanosec"):
        return int(value.sec) * 1_000_000_000 + int(value.nanosec)
    return int(round(float(value) * 1e9))                             # a time field in seconds


def read_bag(path: str | Path, wanted: Collection[str], clock: str = STAMP, strict: bool = True
             ) -> dict[str, tuple[list[str], dict[str, np.ndarray], list[int]]]:
    """The topics of the bag at ``path`` that ``wanted`` columns name, each as (header, its
    columns by name with the clock column ``clock`` in seconds from the first stamp of these
    topics, each sample's message number from 1). ``strict``: a column that names no topic of
    the bag is an error (the run's only logs are bags), else it is left for other files."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file", file=str(path))
    reader = _reader(path)
    refused = _refusals()
    try:
        reader.open()
    except refused as exc:            # rosbags' own errors: a damaged or foreign file
        raise InputError(f"not a readable ROS bag: {exc}", file=str(path)) from None
    try:
        types = {c.topic: c.msgtype for c in reader.connections}
        fields: dict[str, list[Field]] = {}
        for column in wanted:
            if column == clock:
                continue
            field = parse_field(column, types)
            if field is None:
                if strict and column.startswith("/"):
                    shown = ", ".join(f"{t} ({m})" for t, m in sorted(types.items()))
                    raise InputError(f"no topic of the bag starts the column {column!r} (topics: {shown}); a column "
                                     "is TOPIC.FIELD, e.g. /joint_states.position[joint_1]", file=str(path))
                continue
            fields.setdefault(field.topic, []).append(field)
        out: dict[str, tuple[list[str], dict[str, np.ndarray], list[int]]] = {}
        stamps: dict[str, np.ndarray] = {}
        for topic, used in fields.items():
            connections = [c for c in reader.connections if c.topic == topic]
            values: list[list[float]] = [[] for _ in used]
            times: list[int] = []
            names: dict = {}
            for number, (connection, received, raw) in enumerate(reader.messages(connections=connections), start=1):
                try:
                    message = reader.deserialize(raw, connection.msgtype)
                except refused as exc:
                    raise InputError(f"message {number} of topic {topic} cannot be read: {exc}",
                                     file=str(path)) from None
                times.append(_stamp_ns(message, clock, received, topic, connection.msgtype, path))
                for k, field in enumerate(used):
                    try:
                        values[k].append(_value(message, field, names))
                    except (KeyError, AttributeError, IndexError, TypeError, ValueError) as exc:
                        raise InputError(_field_error(field, message, connection.msgtype, exc),
                                         file=str(path), key=f"topic {topic}, message {number}") from None
            if not times:
                raise InputError(f"topic {topic} has no messages", file=str(path))
            stamp = np.asarray(times, dtype=np.int64)
            if clock != LOG_TIME and len(stamp) > 1 and np.all(stamp == stamp[0]):
                raise InputError(f"every message of topic {topic} is stamped {stamp[0] * 1e-9:.9g} s ({clock}): a "
                                 "publisher that does not stamp its messages; read it on the recorder's clock with "
                                 f"time = \"{LOG_TIME}\" in [recording]", file=str(path), key="recording.time")
            order = np.argsort(stamp, kind="stable")     # messages in the order received: by their stamps
            stamps[topic] = stamp[order]
            table = {f.column: np.asarray(v, dtype=float)[order] for f, v in zip(used, values)}
            for field in used:           # a joint in no message: a typo, not missing samples
                joints = [str(step) for kind, step in field.steps if kind == "joint"]
                if joints and np.isnan(table[field.column]).all():
                    listed = sorted({n for key in names for n in key})
                    raise InputError(f"no message of topic {topic} names the joint {joints[0]!r} of {field.column!r} "
                                     f"(joints: {', '.join(listed) or 'none named'}; a value may be taken by its index "
                                     "too, e.g. position[0])", file=str(path))
            out[topic] = ([clock] + [f.column for f in used], table, [int(k) + 1 for k in order])
        if stamps:                   # seconds from the first stamp: exact steps, a shared origin
            origin = min(int(s.min()) for s in stamps.values())
            for topic, (_, table, _) in out.items():
                table[clock] = (stamps[topic] - origin) * 1e-9
        return out
    finally:
        reader.close()


def _field_error(field: Field, message: Any, msgtype: str, exc: Exception) -> str:
    """Why a field path finds no number in a message, with what the message has there."""
    value = message
    for kind, step in field.steps:
        if kind == "attr":
            if not hasattr(value, str(step)):
                known = [n for n in getattr(value, "__dataclass_fields__", {}) if not n.startswith("_")]
                return (f"{msgtype} has no field {step!r} in {field.column!r}"
                        + (f" (fields: {', '.join(known)})" if known else ""))
            value = getattr(value, str(step))
        elif kind == "index":
            try:
                value = value[int(step)]
            except (IndexError, TypeError):
                size = len(value) if hasattr(value, "__len__") else 0
                return f"{field.column!r}: index {step} is outside its {size} values"
        else:
            listed = _joint_names(message, message)
            if listed is not None and hasattr(value, "__len__") and len(value) < len(listed):
                return (f"{field.column!r}: the message's {field.steps[-2][1]} has {len(value)} values for its "
                        f"{len(listed)} joints (a publisher that does not fill it): map this quantity from another "
                        "topic, or leave it out")
            if listed is None:
                return (f"{field.column!r}: [{step}] names a joint, and the message has no list of joint names "
                        f"there (name, joint_names)")
            return f"{field.column!r}: [{step}] cannot be read in this message ({type(exc).__name__}: {exc})"
    return f"{field.column!r} is not a number in {msgtype} ({type(value).__name__}: give a numeric field)"

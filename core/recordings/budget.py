"""How many bytes of a log may be read: one budget for every reader (CSV text, arrays), so a
file too large for memory is refused before it is parsed, whatever its format."""

MAX_FILE_BYTES = 2_000_000_000
# Reading a CSV takes at most about this many bytes of memory per byte of text (the bytes and
# the text, a batch of the used fields' strings, the used columns as floats: measured 2.9 on a
# 147 MB log of 101 columns and 4.0 on a 116 MB one of 15, reading and filtering included): a
# file is refused before it is parsed when that exceeds BASEPARAMS_MAX_MEMORY (default 2 GiB,
# so about 350 MB of text). It was 30 while every field of every row was kept as a string.
PARSE_BYTES_PER_BYTE = 6


def read_budget() -> int:
    """The most bytes of text a data file may have: BASEPARAMS_MAX_MEMORY over what parsing
    takes per byte, and at most MAX_FILE_BYTES."""
    from baseparams.dynamics.trajectory import memory_limit
    return min(MAX_FILE_BYTES, memory_limit() // PARSE_BYTES_PER_BYTE)

"""Argument types of the command line: text -> value, or one message naming the text.

Each type checks the form of one value (a number, a vector, a count, a size, a seed, a
list); sizes are bounded later by ``_bounds``, against each other and the memory. argparse
turns the ``ArgumentTypeError`` into "argument --x: <message>" (exit status 2).
"""

import argparse
import math
import os
import re

EXIT_CODES_HELP = (
    "exit status: 0 success; 2 bad input (one line on stderr, nothing run); 3 the state became "
    "non-finite (what was computed is kept); 130 interrupted by SIGINT or SIGTERM (finished work is kept)"
)

# argparse takes "-0.6,0,0.8" or "-inf" for an option; the parsers have no option that looks
# like a number, so anything starting with "-digit", "-.digit", "-inf" or "-nan" is a value.
NEGATIVE_NUMBER = re.compile(r"^-(\.?\d|inf|nan)", re.IGNORECASE)


def number(text: str, name: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number ({name})") from None


def vector(name: str, size: int, what: str):
    """argparse type: ``size`` comma-separated finite numbers."""

    def parse(text: str):
        parts = [p.strip() for p in str(text).split(",")]
        empty = [i + 1 for i, p in enumerate(parts) if p == ""]
        if len(parts) != size or empty:
            problem = (f"value {empty[0]} is empty" if empty and len(parts) == size else
                       f"got {len(parts)} value{'s' if len(parts) != 1 else ''}")
            raise argparse.ArgumentTypeError(f"needs {size} comma-separated numbers {what}, got {text!r} ({problem})")
        values = tuple(number(p, name) for p in parts)
        if not all(math.isfinite(v) for v in values):
            raise argparse.ArgumentTypeError(f"must be finite numbers, got {text!r}")
        return values

    return parse


def vector3(name: str, what: str = "a,b,c"):
    return vector(name, 3, what)


def positive_list(name: str):
    """argparse type: one or more comma-separated positive finite numbers."""

    def parse(text):
        parts = [p.strip() for p in str(text).split(",") if p.strip() != ""]
        if not parts:
            raise argparse.ArgumentTypeError(f"needs one or more comma-separated numbers, got {text!r}")
        values = tuple(number(p, name) for p in parts)
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise argparse.ArgumentTypeError(f"must be positive finite numbers, got {text!r}")
        return values

    return parse


MAX_TIMES_FILE = 2**28  # bytes of a --save-at @file (read whole, one time per line)


def times(option: str):
    """argparse type: comma-separated finite times, or ``@file`` with one time per line (blank
    lines and lines starting with # are skipped). The order and the range are checked against
    the run later."""

    def parse(text):
        text = str(text)
        if text.startswith("@"):
            items = _times_file(text[1:], option)
        else:
            parts = [p.strip() for p in text.split(",")]
            if all(p == "" for p in parts):
                raise argparse.ArgumentTypeError(f"names no times (got {text!r}); give t1,t2,... or @FILE")
            empty = [i + 1 for i, p in enumerate(parts) if p == ""]
            if empty:
                raise argparse.ArgumentTypeError(f"value {empty[0]} of {text[:60]!r} is empty")
            items = [(None, p) for p in parts]
        values = []
        for line, item in items:
            where = f"line {line} of {text[1:]!r}: " if line is not None else ""
            try:
                value = float(item)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{where}{item[:40]!r} is not a number (a time)") from None
            if not math.isfinite(value):
                raise argparse.ArgumentTypeError(f"{where}times must be finite, got {item!r}")
            values.append(value)
        return tuple(values)

    return parse


def _times_file(path: str, option: str):
    """[(line number, text)] of a times file, refused unless it is a readable regular file of
    bounded size (a FIFO or a device would block or never end)."""
    if path == "":
        raise argparse.ArgumentTypeError("@ must be followed by a file name (@times.txt)")
    if not os.path.exists(path):
        raise argparse.ArgumentTypeError(f"no such file {path!r}")
    if not os.path.isfile(path):
        raise argparse.ArgumentTypeError(f"{path!r} is not a regular file")
    size = os.path.getsize(path)
    if size > MAX_TIMES_FILE:
        raise argparse.ArgumentTypeError(f"{path!r} is {size:,} bytes, more than the {MAX_TIMES_FILE:,} allowed "
                                         "(it is read whole)")
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise argparse.ArgumentTypeError(f"cannot read {path!r} ({type(err).__name__})") from None
    items = [(k + 1, line.strip()) for k, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")]
    if not items:
        raise argparse.ArgumentTypeError(f"{path!r} holds no times (one time per line)")
    return items


def positive_int(text) -> int:
    """argparse type: an integer >= 1; accepts 10000, 10_000 and 1e4."""
    return _integer(text, 1, "a positive integer (>= 1)")


def seed(text) -> int:
    """argparse type: a random seed, an integer in [0, 2^64)."""
    from ._bounds import MAX_SEED

    value = _integer(text, 0, "a seed, an integer >= 0")
    if value > MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be a seed below 2^64, got {text!r}")
    return value


def _integer(text, minimum: int, what: str) -> int:
    s = str(text).strip().replace("_", "")
    try:
        value = int(s)
    except ValueError:
        try:
            f = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
        if not (math.isfinite(f) and f == int(f)):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}") from None
        value = int(f)
    if value < minimum:
        raise argparse.ArgumentTypeError(f"must be {what}, got {text!r}")
    return value


def nonzero_float(text) -> float:
    """argparse type: a finite, non-zero number (a step size; negative integrates backwards)."""
    value = number(text, "step size")
    if not math.isfinite(value) or value == 0:
        raise argparse.ArgumentTypeError(f"must be a finite non-zero number, got {text!r}")
    return value


def positive_float(text) -> float:
    value = number(text, "positive number")
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite positive number, got {text!r}")
    return value


def nonnegative_float(text) -> float:
    value = number(text, "number")
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


_SIZE = re.compile(r"^\s*([0-9.]+(?:e[+-]?\d+)?)\s*([kmgt]?)i?b?\s*$", re.IGNORECASE)


def byte_size(text) -> int:
    """argparse type: a memory size such as 500M, 2G, 1.5GiB or a plain byte count (>= 1 byte)."""
    match = _SIZE.match(str(text))
    if not match:
        raise argparse.ArgumentTypeError(f"must be a size like 500M or 2G, got {text!r}")
    try:
        value = float(match.group(1)) * 1024 ** " kmgt".index(match.group(2).lower() or " ")
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a size like 500M or 2G, got {text!r}") from None
    if not math.isfinite(value) or value < 1:
        raise argparse.ArgumentTypeError(f"must be a size of at least 1 byte, got {text!r}")
    return int(value)


def names(option: str):
    """argparse type: a comma-separated list of one or more names."""

    def parse(text):
        items = [p.strip() for p in str(text).split(",") if p.strip()]
        if not items:
            raise argparse.ArgumentTypeError(f"names no {option.lstrip('-')} (got {text!r})")
        return items

    return parse


def add_common_flags(p, *, outputs=True, json_flag=True, quiet=True):
    if outputs:
        p.add_argument("--force", action="store_true", help="overwrite existing output files")
    if json_flag:
        p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    if quiet:
        p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")


def given_options(parser, command: str, argv) -> frozenset:
    """The destinations of the options the user gave to ``command`` (set by ``main`` as
    ``args.given``): the command line parsed once more with every default suppressed."""
    sub = parser.commands.choices[command]
    saved = [(action, action.default) for action in sub._actions]
    try:
        for action, _ in saved:
            action.default = argparse.SUPPRESS
        return frozenset(vars(parser.parse_args(argv))) - {"command", "func"}
    finally:
        for action, default in saved:
            action.default = default


def refuse_unused(args, rules: dict) -> None:
    """The one check that no option the user gave is silently ignored: ``rules`` maps an
    option's destination to (whether it takes effect in this run, where it applies); one
    given (``args.given``) that takes none is an error naming it and where it applies."""
    given = getattr(args, "given", frozenset())
    for dest, (effective, where) in rules.items():
        if dest in given and not effective:
            from .._errors import InputError

            raise InputError(f"--{dest.replace('_', '-')} has no effect here: it applies only {where}")

"""The ``jaxsplit`` command line: one module per subcommand, registered in ``COMMANDS``.

Each subcommand module exposes ``add_parser(subparsers)`` (which sets ``func``). Bad input
raises ``InputError`` anywhere below; ``main`` turns it into one line on stderr and exit
status 2, never a traceback. The CLI runs in float64.
"""

import argparse
import importlib
import re
import sys

from ..core._errors import InputError

COMMANDS = ("simulate", "schemes", "check", "sweep", "fit", "paper")

DESCRIPTION = ("jaxsplit: structure-preserving (Poisson / symplectic) splitting integrators for the "
               "free rigid body, in JAX.")

EPILOG = """\
examples:
  jaxsplit simulate                       # the paper's symmetric body with Lie-Trotter
  jaxsplit schemes
  jaxsplit check --scheme kahan-li-6 --split casimir
  jaxsplit COMMAND --help                 # options and examples of each command

exit status: 0 success; 1 `check` found a failed check; 2 bad input (one line on stderr,
nothing run); 3 the state became non-finite (what was computed is kept); 130 interrupted
(finished work is kept; `sweep --resume` continues).
"""

# argparse treats "-0.6,0,0.8" as an option; these parsers have no option that looks
# like a number, so anything starting with "-digit" or "-.digit" is a value.
_NEGATIVE_NUMBER = re.compile(r"^-\.?\d")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit status 2) instead of usage dumps."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message):
        raise InputError(f"{self.prog}: {message}")


def _load(name):
    """The subcommand module, or None when it is not installed (yet)."""
    module_name = f"{__name__}.{name}"
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name == module_name:
            return None
        raise


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="jaxsplit", description=DESCRIPTION, epilog=EPILOG,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"jaxsplit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in dict.fromkeys(COMMANDS):
        module = _load(name)
        if module is not None:
            module.add_parser(sub)
    return parser


def main(argv=None) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 0
        return args.func(args) or 0
    except InputError as err:
        print(f"jaxsplit: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("jaxsplit: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `jaxsplit schemes | head`
        return 0


def _one_line(err) -> str:
    return " ".join(str(err).split())


if __name__ == "__main__":
    sys.exit(main())

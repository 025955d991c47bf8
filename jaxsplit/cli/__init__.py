"""The ``jaxsplit`` command line: one module per subcommand, registered in ``COMMANDS``.

Each subcommand module exposes ``add_parser(subparsers)`` (which sets ``func``). Bad input
raises ``InputError`` anywhere below; ``main`` turns it into one line on stderr and exit
status 2, never a traceback. The CLI runs in float64.
"""

import argparse
import importlib
import sys

from .._errors import InputError

COMMANDS = ("simulate", "schemes")


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit status 2) instead of usage dumps."""

    def error(self, message):
        raise InputError(f"{self.prog}: {message}")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="jaxsplit", description=__doc__.splitlines()[0],
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"jaxsplit {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMANDS:
        importlib.import_module(f".{name}", __name__).add_parser(sub)
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
        print(f"jaxsplit: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("jaxsplit: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

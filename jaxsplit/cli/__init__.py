"""The ``jaxsplit`` command line: one module per subcommand, registered in ``COMMANDS``.

Each subcommand module exposes ``add_parser(subparsers)`` (which sets ``func``). Bad input
raises ``InputError`` anywhere below; ``main`` turns it into one line on stderr and exit
status 2, never a traceback. SIGINT and SIGTERM follow the one policy of ``_signals``,
installed first thing in ``main``, before JAX is imported (importing this package loads
neither JAX nor NumPy): exit status 130, with finished work written. The CLI runs
in float64.

Shared pieces, one concept each: ``_args`` (argument types), ``_bounds`` (every size a
user controls), ``_io`` (the one writer: resolved, locked, atomic outputs), ``_metadata``
(what a run records; JSON on stdout), ``_signals`` (the signal policy), ``_progress`` (the
progress bar), ``_chunked`` (long runs in chunks), ``_problem`` (system, state, scheme and
split), ``_diagnostics`` (invariant errors, the exact solution), ``_data`` (the one
trajectory format, npz and csv: what simulate writes and fit reads), ``_figures`` (simulate's
and sweep's figures). ``python -m jaxsplit`` runs the same ``main``.
"""

import argparse
import importlib
import sys

from .._errors import InputError
from . import _args, _signals

COMMANDS = ("simulate", "schemes", "check", "sweep", "fit", "paper", "spins-audit")

DESCRIPTION = ("jaxsplit: structure-preserving (Poisson / symplectic) splitting integrators for rigid "
               "bodies (free, with attitude, heavy top, gravity gradient), in JAX.")

EPILOG = """\
examples:
  jaxsplit simulate                       # the paper's symmetric body with Lie-Trotter
  jaxsplit schemes
  jaxsplit check --scheme kahan-li-6 --split casimir
  jaxsplit simulate --system heavy-top --t-end 20 --save-every 20 --out top.npz && jaxsplit fit --data top.npz
  jaxsplit COMMAND --help                 # options and examples of each command

exit status: 0 success; 1 `check` found a failed check; 2 bad input (one line on stderr,
nothing run); 3 the state became non-finite (what was computed is kept); 130 interrupted
(finished work is kept; `sweep --resume` continues).
"""

class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit status 2) instead of usage dumps."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _args.NEGATIVE_NUMBER

    def error(self, message):
        raise InputError(f"{self.prog}: {message}")


def _load(name):
    """The subcommand module, or None when it is not installed (yet)."""
    module_name = f"{__name__}.{name.replace('-', '_')}"
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
    parser.commands = sub
    for name in dict.fromkeys(COMMANDS):
        module = _load(name)
        if module is not None:
            module.add_parser(sub)
    return parser


def main(argv=None) -> int:
    """Run the command line on ``argv`` (default: ``sys.argv[1:]``, the process's own
    arguments: then ``main`` is the process and ends it, ``_signals.end_process``: a signal
    at any moment before the process is gone makes its status 130)."""
    with _signals.policy() as stop:
        status = _run(argv, stop)
        if status != _signals.EXIT_INTERRUPTED:
            from ..distributed import leave

            leave()  # several processes: wait for the others before ending (see leave)
        if argv is None:
            _signals.end_process(status, stop)
    return status


def _run(argv, stop) -> int:
    from .._xla_cpu import tune_cpu

    tune_cpu()  # the command line's own runs: 512-bit vectors (before JAX starts its backend)
    import jax

    jax.config.update("jax_enable_x64", True)
    try:
        from ..distributed import initialize_from_env

        initialize_from_env()  # one of several processes (python -m jaxsplit.launch): join them
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 0
        args.given = _args.given_options(parser, args.command, argv)  # for _args.refuse_unused
        status = args.func(args) or 0
    except InputError as err:
        print(f"jaxsplit: error: {_one_line(err)}", file=sys.stderr)
        return 2
    except _signals.Interrupted as stopped:
        if stopped.detail:
            print(f"jaxsplit: interrupted ({stopped}); {stopped.detail}", file=sys.stderr)
        return _signals.EXIT_INTERRUPTED
    except BrokenPipeError:  # `jaxsplit schemes | head`
        return 0
    if stop.requested and status == 0:  # the signal came while the outputs were written: they are complete
        print(f"jaxsplit: interrupted ({stop.signal_name}) after the work was done; "
              "every output is complete", file=sys.stderr)
        return _signals.EXIT_INTERRUPTED
    return status


def _one_line(err) -> str:
    return " ".join(str(err).split())


if __name__ == "__main__":
    sys.exit(main())

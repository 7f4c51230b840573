"""``intersection-estimator``: one command line with a subcommand per job.

Each subcommand lives in the module that does the work and registers itself there
(``register(subparsers)`` adds its parser and ``set_defaults(func=handler)``).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__

#: subcommand modules, in the order ``--help`` lists them
SUBCOMMANDS = (
    'intersection_estimator.replay',       # replay, demo
    'intersection_estimator.sim.cli',      # simulate
    'intersection_estimator.evaluate',     # evaluate
    'intersection_estimator.bench',        # bench
    'intersection_estimator.soak',         # soak
    'intersection_estimator.realdata.av2', # av2
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='intersection-estimator',
        description='Map-free lane-level intersection estimation (Meyer et al., ITSC 2019): '
                    'replay bags, simulate scenarios, evaluate and benchmark.')
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    for name in SUBCOMMANDS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, 'func', None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())

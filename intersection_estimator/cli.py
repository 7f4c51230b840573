"""``intersection-estimator``: one command line with a subcommand per job.

Each subcommand lives in the module that does the work and registers itself there
(``register(subparsers)`` adds its parser and ``set_defaults(func=handler)``).
"""

from __future__ import annotations

import argparse
import importlib
import re
import sys

from . import __version__

#: subcommand modules, in the order ``--help`` lists them
SUBCOMMANDS = (
    'intersection_estimator.replay',       # replay, demo
    'intersection_estimator.sim.cli',      # simulate
    'intersection_estimator.evaluate',     # evaluate
    'intersection_estimator.bench',        # bench
    'intersection_estimator.soak',         # soak
    'intersection_estimator.fleet.cli',    # fleet
    'intersection_estimator.realdata.av2', # av2
)


class ArgumentParser(argparse.ArgumentParser):
    """argparse with one-line errors (``PROG: error: ...``, exit ``usage_exit``: 2 as argparse,
    unless a subcommand documents another code for bad arguments) and help text without
    Sphinx markup (the subcommands' descriptions are their module docstrings)."""

    usage_exit = 2

    def error(self, message: str):
        self.exit(self.usage_exit, f'{self.prog}: error: {" ".join(message.split())}\n')

    def format_help(self) -> str:
        return plain_doc(super().format_help())


_ROLE = re.compile(r':(?:[a-z]+:)?[a-z]+:`~?\.*([^`<]*?)(?:\s*<[^>]*>)?`')


def plain_doc(text: str | None) -> str | None:
    """Sphinx / reST markup out of a docstring for the terminal: ``:class:`~.a.B``` -> ``B``,
    ````x```` -> ``x``, ``:data:`.X``` -> ``X``; ``\\`` escapes dropped."""
    if not text:
        return text

    def role(m):
        name = m.group(1)
        return name.rsplit('.', 1)[-1] if m.group(0).count('~') else name
    text = _ROLE.sub(role, text)
    return text.replace('``', '').replace('\\ ', '')


def int_at_least(minimum: int):
    """argparse ``type``: an integer >= ``minimum`` (a clear one-line error otherwise)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not an integer') from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f'{value} out of range: must be >= {minimum}')
        return value
    parse.__name__ = f'integer >= {minimum}'
    return parse


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
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

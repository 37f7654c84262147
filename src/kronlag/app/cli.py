"""Command-line interface: a thin shell over the Python API.

MODEL is the name of a built-in model or shipped example (``kronlag models``
lists them) or the path of a TOML model file (format: :mod:`kronlag.modelfile`) or of a robot
file (``.urdf``: :func:`kronlag.load_urdf`; ``.xml`` MJCF: :func:`kronlag.load_mjcf`; ``.sdf``:
:func:`kronlag.load_sdf`).

Exit status: 0 success; 2 bad input, found before any computation (one line
on stderr, no traceback); 1 the run did not complete: a numerical failure or an
output that could not be written (the other outputs are written, and what was
computed is saved; stderr says where); 130 interrupted (Ctrl-C; what finished is
saved, stderr says where).

The exit status follows the class of what went wrong (:data:`EXIT_CODES`, the hierarchy of
:mod:`kronlag.core.errors`): bad input (:class:`~kronlag.core.errors.InputError`, an unreadable
file) is 2, an incomplete run (:class:`~kronlag.core.errors.NumericalError`,
:class:`~kronlag.core.errors.CompilerError`, :class:`~kronlag.app.outputs.IncompleteRun`) is 1;
anything else is a bug and shows its traceback.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import textwrap
from collections.abc import Callable, Sequence

from .. import __version__
from ..core.errors import CompilerError, InputError, NumericalError
from ..model.robot_formats.absolute import COORDINATE_CHOICES
from ..numeric.codegen import c_compiler
from . import analysis_commands, commands
from .outputs import IncompleteRun, RunInterrupted

__all__ = ["main", "build_parser", "plain_text", "EXIT_OK", "EXIT_INCOMPLETE", "EXIT_BAD_INPUT", "EXIT_INTERRUPTED",
           "EXIT_CODES"]

EXIT_OK, EXIT_INCOMPLETE, EXIT_BAD_INPUT = 0, 1, 2
#: Ctrl-C (SIGINT), as shells report a command it ended: 128 + 2.
EXIT_INTERRUPTED = 130

#: Exit status and message prefix by exception class, the first match in this order.
EXIT_CODES: tuple[tuple[type[BaseException], int, str], ...] = (
    (RunInterrupted, EXIT_INTERRUPTED, ""),
    (IncompleteRun, EXIT_INCOMPLETE, ""),
    (NumericalError, EXIT_INCOMPLETE, "numerical failure: "),
    (CompilerError, EXIT_INCOMPLETE, "compiled code: "),
    (InputError, EXIT_BAD_INPUT, "error: "),
    (OSError, EXIT_BAD_INPUT, "error: "),
    (KeyboardInterrupt, EXIT_INTERRUPTED, "interrupted: "),
)


#: A reST cross-reference, ``:role:`target``` or ``:role:`~dotted.target```, and inline literals.
_REFERENCE = re.compile(r":[a-z]+:`(~?)([^`<]*?)(?:\s*<([^`>]*)>)?`")
_LITERAL = re.compile(r"``([^`]*)``")


def plain_text(text: str) -> str:
    """Docstring text (reST) as plain text for ``--help``: ``:func:`~a.b.c``` -> ``c``,
    ``:mod:`a.b``` -> ``a.b``, a double-backquoted literal -> its text; paragraphs refilled."""

    def reference(match: re.Match) -> str:
        short, title, target = match.groups()
        if target is not None:  # :role:`title <target>`
            return title.strip()
        return title.rpartition(".")[2] if short else title

    plain = _LITERAL.sub(r"\1", _REFERENCE.sub(reference, text))
    return "\n\n".join(textwrap.fill(" ".join(paragraph.split()), 79) for paragraph in plain.strip().split("\n\n"))


class _Version(argparse.Action):
    """``--version``: the installed version and the C compiler kronlag uses (found on first use)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: object):
        super().__init__(option_strings, dest, nargs=0, help="show the version and the C compiler used, and exit")

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        compiler = c_compiler() or "none found, the Python backend is used (pip install kronlag[compiler])"
        print(f"kronlag {__version__}\nC compiler: {compiler}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    """The ``kronlag`` argument parser."""
    parser = argparse.ArgumentParser(prog="kronlag", description=plain_text(__doc__),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action=_Version)
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, handler: Callable[[argparse.Namespace], None], summary: str,
                *, model: bool = True) -> argparse.ArgumentParser:
        sub = subparsers.add_parser(name, help=summary, description=summary)
        sub.set_defaults(handler=handler)
        if model:
            sub.add_argument("model", metavar="MODEL", help="built-in model name or path of a TOML model file or a .urdf, .xml (MJCF) or .sdf robot file")
            sub.add_argument("--floating-base", action="store_true",
                             help="a URDF robot: join its root link to the world by a floating joint 'root_joint' "
                                  "(legged robots' files leave it out)")
            sub.add_argument("--coordinates", choices=COORDINATE_CHOICES, default="joint",
                             help="a robot file: joint coordinates (default) or absolute body coordinates")
        return sub

    commands.add_commands(command)
    analysis_commands.add_commands(command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line ``argv`` (default: ``sys.argv[1:]``); returns the exit status."""
    try:
        arguments = build_parser().parse_args(argv)
    except SystemExit as exit_request:  # --help, or a usage error (argparse printed it)
        return int(exit_request.code or 0)
    try:
        arguments.handler(arguments)
    except BrokenPipeError:  # the reader of standard output quit early (| head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except tuple(kind for kind, _, _ in EXIT_CODES) as error:
        status, prefix = next((status, prefix) for kind, status, prefix in EXIT_CODES if isinstance(error, kind))
        print(f"kronlag: {prefix}{error}" if str(error) else f"kronlag: {prefix.removesuffix(': ')}", file=sys.stderr)
        return status
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())

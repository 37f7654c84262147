"""Command-line interface: a thin shell over the Python API."""

from __future__ import annotations

import argparse
import sys

from . import models
from .derivation import derive


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="kronlag", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    derive_parser = commands.add_parser("derive", help="derive and print the equations of a built-in model")
    derive_parser.add_argument("model", choices=sorted(models.BUILTIN_MODELS))
    derive_parser.add_argument("--simplify", action="store_true", help="apply trigsimp to every entry")
    arguments = parser.parse_args(argv)
    equations = derive(models.BUILTIN_MODELS[arguments.model](), simplify=arguments.simplify)
    print(equations)
    return 0


if __name__ == "__main__":
    sys.exit(main())

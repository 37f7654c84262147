"""``python -m kronlag``: the command line (:mod:`kronlag.app.cli`)."""

import sys

from .app.cli import main

sys.exit(main())

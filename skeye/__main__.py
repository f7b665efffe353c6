"""``python -m skeye``: the ``skeye`` command line (:func:`skeye.cli.main`), for a Python whose
scripts folder is not on PATH (``.venv/bin/python -m skeye up``)."""

import sys

from skeye.cli import main

if __name__ == "__main__":
    sys.exit(main())

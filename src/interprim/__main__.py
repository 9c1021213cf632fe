"""``python -m interprim COMMAND ...``: the command line, the same as the ``interprim`` script."""

import sys

from .cli import main

sys.exit(main())

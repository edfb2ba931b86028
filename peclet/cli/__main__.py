"""``python -m peclet.cli``: the same as the ``peclet`` command."""
import sys

from peclet.cli import main

sys.exit(main())

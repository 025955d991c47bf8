"""``python -m jaxsplit``: the ``jaxsplit`` command (the same ``main``, the same exit statuses)."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())

"""``python -m tortwin.fleet MANIFEST``: the command ``tortwin-fleet``."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())

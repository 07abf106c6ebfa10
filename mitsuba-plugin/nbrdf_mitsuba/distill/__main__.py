"""``python -m nbrdf_mitsuba.distill``."""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())

"""Entry point of `make demo`: see nbrdf_tools.demo (also ``python -m nbrdf_tools demo``)."""

import sys

from nbrdf_tools.demo import main

if __name__ == "__main__":
    sys.exit(main())

import sys

from nbrdf_tools.pages.fidelity.command import main

sys.exit(main())

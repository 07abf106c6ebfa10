import sys

from nbrdf_tools.convergence.command import main

sys.exit(main())

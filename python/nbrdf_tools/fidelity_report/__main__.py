import sys

from nbrdf_tools.fidelity_report.command import main

sys.exit(main())

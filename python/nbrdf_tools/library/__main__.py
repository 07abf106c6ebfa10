import sys

from nbrdf_tools.library.main import main

sys.exit(main())

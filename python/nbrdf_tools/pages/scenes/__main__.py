import sys

from nbrdf_tools.pages.scenes.command import main

sys.exit(main())

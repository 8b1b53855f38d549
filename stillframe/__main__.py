import sys

from stillframe.app.cli import main

sys.exit(main())

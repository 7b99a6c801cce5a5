import sys

from diviewer.cli import main

sys.exit(main())

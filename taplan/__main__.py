import sys

from taplan.cli import main

sys.exit(main())

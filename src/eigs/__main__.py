import sys

from eigs.cli import main

sys.exit(main())

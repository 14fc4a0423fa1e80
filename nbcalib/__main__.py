"""``python -m nbcalib`` runs the command line."""

import sys

from nbcalib.cli import main

sys.exit(main())

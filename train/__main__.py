"""``python -m train`` runs the ``nbs`` command line."""

import sys

from train.cli import main

sys.exit(main())

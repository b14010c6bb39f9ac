"""``python -m lhgraph`` runs the CLI."""

import sys

from lhgraph.cli import main

sys.exit(main())

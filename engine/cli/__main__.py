"""``python -m engine.cli``: the buildingparser command line."""
import sys

from engine.cli import main

sys.exit(main())

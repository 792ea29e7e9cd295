"""``python -m petsc_htp.bench``."""
import sys

from . import main

sys.exit(main())

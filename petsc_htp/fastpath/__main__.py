"""``python -m petsc_htp.fastpath``: run the fast-path benchmark command line."""
import sys

from .run import main

if __name__ == "__main__":
    sys.exit(main())

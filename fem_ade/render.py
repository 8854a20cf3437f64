"""``python -m fem_ade.render``: a run folder's pictures (:mod:`fem_ade.plots.render`, where the
code is)."""

import sys

from fem_ade.plots.render import main

if __name__ == "__main__":
    sys.exit(main())

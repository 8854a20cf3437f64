"""``python -m fem_ade.sweep``: parameter sweeps (:mod:`fem_ade.campaigns.sweep`, where the code
is)."""

import sys

from fem_ade.campaigns.sweep import main

if __name__ == "__main__":
    sys.exit(main())

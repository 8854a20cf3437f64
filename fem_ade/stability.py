"""``python -m fem_ade.stability``: the stability of a steady state
(:mod:`fem_ade.campaigns.stability`, where the code is)."""

import sys

from fem_ade.campaigns.stability import main

if __name__ == "__main__":
    sys.exit(main())

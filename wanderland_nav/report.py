"""The multi-seed table: `python -m wanderland_nav.report outputs/<exp>/*_seed*/results.json [--baseline BC]`.

The tables themselves live in `wanderland_nav.evaluation.tables`; this is its command line.
"""

import sys

from wanderland_nav.evaluation.tables import main

if __name__ == "__main__":
    main(sys.argv[1:])

"""`python -m tatl_mj.cli`: the `tatl` command."""

import sys

from tatl_mj.cli import main

sys.exit(main())

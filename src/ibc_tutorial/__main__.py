import sys

from ibc_tutorial.cli import main

sys.exit(main())

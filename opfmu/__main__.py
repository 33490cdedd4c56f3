import sys

from opfmu.cli import main

sys.exit(main())

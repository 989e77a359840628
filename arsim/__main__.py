import sys

from arsim.cli import main

sys.exit(main())

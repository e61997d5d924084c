import sys

from rolling_env.cli.main import main

sys.exit(main())

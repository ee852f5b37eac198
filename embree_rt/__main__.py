import sys

from embree_rt.cli import main

sys.exit(main())

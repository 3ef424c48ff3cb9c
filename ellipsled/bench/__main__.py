"""``python -m ellipsled.bench [--quick] [--out FILE.json] [--only a,b]`` (= ``ellipsled bench``)."""
import sys

from .suite import main

sys.exit(main())

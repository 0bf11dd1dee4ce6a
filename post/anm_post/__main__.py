"""`python -m anm_post` runs the anm-post command line."""
import sys

from .cli import main

sys.exit(main())

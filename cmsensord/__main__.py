"""`python -m cmsensord` = the `cmsensord` command."""
import sys

from cmsensord.cli import main

sys.exit(main())

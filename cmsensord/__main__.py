"""`python -m cmsensord` = the `cmsensord` command (:mod:`cmsensord.entry`)."""
import sys

from cmsensord.entry import main

sys.exit(main())

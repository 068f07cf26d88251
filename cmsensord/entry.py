"""The ``cmsensord`` command's entry point (the console script, and ``python -m cmsensord``).

Its first act, before the command line's imports (~0.3 s), is to hold SIGHUP
(:func:`cmsensord.hangup.hold`): a ``systemctl reload`` while the daemon starts is a reopen of
its logs, not the end of the process.
"""

from cmsensord import hangup


def main() -> int:
    """Hold SIGHUP, then run :func:`cmsensord.cli.main`; its exit status."""
    hangup.hold()
    from cmsensord.cli import main as cli_main

    return cli_main()

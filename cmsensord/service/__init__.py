"""What the daemon's commands do: the live loop, replay, record, simulate and summary.

``cmsensord.cli`` parses the command line and calls these; each is usable without it.
"""

"""The monitoring chain: decoded frames -> parts with one job each -> messages and events.

See docs/architecture.md for one frame's path through it; :mod:`.processor` routes.
"""

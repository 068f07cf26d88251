"""Publishing to an MQTT broker with disk-backed store-and-forward (the ``mqtt`` section).

:mod:`.disk_queue` keeps every message until the broker acknowledged it, :mod:`.topics` maps
MCAP topics to MQTT topics and payloads, :mod:`.publisher` runs the paho-mqtt client in its own
thread. Nothing here imports paho until a publisher starts.
"""

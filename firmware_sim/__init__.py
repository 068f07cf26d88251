"""firmware_sim: the simulated TM4C1294 ADC board (see PROTOCOL.md)."""

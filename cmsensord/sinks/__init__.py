"""Output sinks (MCAP)."""

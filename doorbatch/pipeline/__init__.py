"""Pipeline stages: pure functions from typed records to typed results (no file I/O, no printing)."""

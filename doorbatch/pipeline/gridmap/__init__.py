"""Grid stage: occupancy grid mapping with door detection (paper 000, Sec. III)."""

"""I/O at the edges: task and map YAML, DXF floor plans, atomic output."""

"""Discovery: what the simulation gets wrong, its cause, the extended model."""

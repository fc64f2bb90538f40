"""Gray-box identification of the winch (or axis) model from measured data."""

"""float64 reference implementations of the firmware's operators and models."""

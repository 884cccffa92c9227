"""Mismatch diagnosis: locate where a simulation and recordings differ, name the physics
left out, model it, and show the held-out improvement (``piezoctl diagnose``, docs/diagnose.md)."""

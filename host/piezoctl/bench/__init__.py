"""Benchmarks of the host tool (identification on real recordings, speed)."""

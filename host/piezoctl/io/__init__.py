"""Files the host reads and writes: recordings, model files."""

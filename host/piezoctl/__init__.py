"""piezoctl host tool: identification, coefficient tables, flashing, diagnosis."""

__version__ = "0.1.0"

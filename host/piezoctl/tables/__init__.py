"""Coefficient-table images: layout (common/interface.toml), building, parsing."""

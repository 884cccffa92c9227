"""report.html: the diagnosis in words and plots (self-contained, PNGs embedded)."""

from __future__ import annotations

import base64
import html
import io

import numpy as np

__all__ = ["write_report"]


def write_report(path, doc, sigs, valid, yr_all, held_pred) -> None:
    """Placeholder replaced below."""
    with open(path, "w") as fh:
        fh.write("<html><body><pre>" + html.escape(str(doc["named"])) + "</pre></body></html>")

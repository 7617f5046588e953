"""Atomic writes of a sweep's files: a temporary file in the same folder, then a rename."""

from __future__ import annotations

import io
from pathlib import Path

from shipsense.fileio import atomic_write_bytes  # noqa: F401  (re-exported: the sweep and reproduce use it)


def write_table(path: Path, table: dict | object) -> None:
    """Write a table (``{column: list}`` or a DataFrame) as Parquet (or CSV by suffix), atomically."""
    import pandas as pd

    df = table if isinstance(table, pd.DataFrame) else pd.DataFrame(table)
    buf = io.BytesIO()
    if path.suffix == ".csv":
        buf.write(df.to_csv(index=False).encode())
    else:
        df.to_parquet(buf, index=False)
    atomic_write_bytes(path, buf.getvalue())

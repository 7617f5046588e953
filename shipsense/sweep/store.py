"""A sweep's tables as files: Parquet (or CSV by suffix), written atomically."""

from __future__ import annotations

import io
from pathlib import Path

from shipsense.atomic import atomic_write_bytes

__all__ = ["atomic_write_bytes", "table_bytes", "write_table"]


def table_bytes(table: dict | object, suffix: str = ".parquet") -> bytes:
    """A table (``{column: list}`` or a DataFrame) as the bytes of a Parquet file (a CSV file for ``.csv``)."""
    import pandas as pd

    df = table if isinstance(table, pd.DataFrame) else pd.DataFrame(table)
    if suffix == ".csv":
        return df.to_csv(index=False).encode()
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    return buf.getvalue()


def write_table(path: Path, table: dict | object) -> None:
    """Write a table (``{column: list}`` or a DataFrame) as Parquet (or CSV by suffix), atomically."""
    atomic_write_bytes(path, table_bytes(table, path.suffix))

"""Reading a saved Rerun recording back in tests."""

from __future__ import annotations

from collections import defaultdict

import pyarrow as pa
from rerun.chunk import RrdReader


def read_rrd(path) -> dict[str, dict[str, list]]:
    """Entity path -> column name -> values (rows of all chunks, sorted by seq)."""
    rows: dict[str, list[dict]] = defaultdict(list)
    for chunk in RrdReader(path).stream().to_chunks():
        if chunk.is_static:
            continue
        rb = chunk.to_record_batch()
        cols = {}
        for i, field in enumerate(rb.schema):
            col = rb.column(i)
            if pa.types.is_timestamp(field.type) or pa.types.is_duration(field.type):
                col = col.cast(pa.int64())  # nanoseconds, without pandas
            cols[field.name] = col.to_pylist()
        for r in range(rb.num_rows):
            rows[chunk.entity_path].append({n: v[r] for n, v in cols.items()})
    out = {}
    for ent, rs in rows.items():
        rs.sort(key=lambda r: r["seq"])
        out[ent] = {n: [r[n] for r in rs] for n in rs[0]}
    return out

"""Many entities' components in one Arrow record batch, sent to Rerun in one call.

Rerun's archetype constructors convert every field in Python, and every ``log`` or ``send_columns``
call crosses into Rust on its own; with some 20 entities per grasp that fixed cost outweighed the data.
A :class:`ColumnBatch` builds each component column straight from numpy, in the Arrow datatype and
with the component descriptor that Rerun's own ``Archetype.columns()`` produces (looked up once per
process and field), and sends all of them with ``RecordingStream.send_record_batch``, which splits the
batch into one chunk per entity (the ``rerun:entity_path`` of each column). The chunks are the same as
those of one ``send_columns`` (temporal) or static ``log`` call per entity.
"""

from __future__ import annotations

from functools import cache, lru_cache
from typing import NamedTuple

import numpy as np
import pyarrow as pa
import rerun as rr

__all__ = ["ColumnBatch", "FIRST_ROW", "rgba32"]

FIRST_ROW = object()
"""``rows`` of :meth:`ColumnBatch.add`: the first row only (the one row of a static batch)."""

_SAMPLES = {
    "vertex_positions": [[0.0, 0.0, 0.0]],
    "triangle_indices": [[0, 1, 2]],
    "vertex_colors": [0],
    "albedo_factor": [0],
    "translation": [[0.0, 0.0, 0.0]],
    "quaternion": [[0.0, 0.0, 0.0, 1.0]],
    "strips": [[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]],
    "origins": [[0.0, 0.0, 0.0]],
    "vectors": [[0.0, 0.0, 0.0]],
    "colors": [0],
    "scalars": [0.0],
    "names": ["x"],
    "text": ["x"],
    "media_type": ["text/plain"],
    "centers": [[0.0, 0.0, 0.0]],
    "half_sizes": [[1.0, 1.0, 1.0]],
    "labels": ["x"],
    "fill_mode": ["solid"],
}
"""One valid value per archetype field that a batch can carry (to ask Rerun for its column layout)."""


@cache
def _component(archetype: str, field: str) -> tuple[dict[str, str], pa.ListType]:
    """Arrow field metadata and list datatype of ``rr.{archetype}``'s ``field``, as Rerun builds them."""
    if field not in _SAMPLES:
        raise ValueError(f"{archetype}.{field} is not a field a ColumnBatch carries")
    (column,) = getattr(rr, archetype).columns(**{field: _SAMPLES[field]})
    d = column.component_descriptor()
    meta = {
        "rerun:kind": "data",
        "rerun:archetype": d.archetype,
        "rerun:component": d.component,
        "rerun:component_type": d.component_type,
    }
    return meta, column.as_arrow_array().type


class _Level(NamedTuple):
    """One nesting level of a component's items: how :func:`_items` builds its Arrow array."""

    kind: str
    """``list`` (variable-size), ``fixed`` (fixed-size list of numbers), ``string`` or ``primitive``."""
    type: pa.DataType
    child: pa.DataType | None
    """The numbers' type of a ``fixed`` level."""
    dtype: np.dtype | None
    """numpy dtype of the numbers (``fixed`` and ``primitive``)."""
    width: int
    """Numbers per item of a ``fixed`` level."""


def _levels(t: pa.DataType) -> tuple[_Level, ...]:
    """The levels of item type ``t``, outermost first.

    Worked out once per component, not per column: hashing or inspecting an Arrow type costs
    microseconds.
    """
    out = []
    while pa.types.is_list(t):
        out.append(_Level("list", t, None, None, 0))
        t = t.value_type
    if pa.types.is_fixed_size_list(t):
        if not pa.types.is_primitive(t.value_type):
            raise ValueError(f"fixed-size lists of {t.value_type} are not supported")
        out.append(_Level("fixed", t, t.value_type, np.dtype(t.value_type.to_pandas_dtype()), t.list_size))
    elif pa.types.is_string(t):
        out.append(_Level("string", t, None, None, 0))
    else:
        out.append(_Level("primitive", t, None, np.dtype(t.to_pandas_dtype()), 0))
    return tuple(out)


@lru_cache(maxsize=4096)
def _field(entity: str, archetype: str, field: str) -> tuple[pa.Field, pa.ListType, tuple[_Level, ...]]:
    """The Arrow field of ``entity``'s column of ``rr.{archetype}``'s ``field``, its type, its levels.

    The type is a list per row; the levels are its items' (:func:`_levels`). Entities recur (every rollout of a design logs the same ones), and a field with its metadata costs
    ~15 us to build.
    """
    meta, t = _component(archetype, field)
    name = f"{entity}:{meta['rerun:component']}"
    return pa.field(name, t, metadata={**meta, "rerun:entity_path": entity}), t, _levels(t.value_type)


def _items(levels: tuple[_Level, ...], data) -> pa.Array:
    """Arrow array of the outermost of ``levels`` from numpy data.

    Rows of a fixed-size list, scalars, strings, or a list of arrays for a variable-size list (strips).
    Numeric data is wrapped as Arrow buffers without a copy once it has the column's dtype
    (``pa.array`` costs ~10 us a call, which adds up over some 40 arrays per grasp).
    """
    kind, t, child, dtype, width = levels[0]
    if kind == "fixed":
        values = np.asarray(data, dtype=dtype).reshape(-1)
        inner = pa.Array.from_buffers(child, len(values), [None, pa.py_buffer(values)])
        return pa.Array.from_buffers(t, len(values) // width, [None], children=[inner])
    if kind == "list":
        return _lists(t, [len(x) for x in data], np.concatenate(data) if len(data) else [], levels[1:])
    if kind == "string":
        return pa.array(list(data), type=t)
    values = np.ascontiguousarray(data, dtype=dtype).reshape(-1)
    return pa.Array.from_buffers(t, len(values), [None, pa.py_buffer(values)])


def _lists(t: pa.ListType, lengths, items, levels: tuple[_Level, ...]) -> pa.ListArray:
    """A list array of type ``t``: ``lengths[i]`` of ``items`` (of ``levels``) in row i."""
    offsets = np.zeros(len(lengths) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    values = _items(levels, items)
    if len(values) != offsets[-1]:
        raise ValueError(f"{len(values)} values for rows of {offsets[-1]} in all")
    return pa.Array.from_buffers(t, len(lengths), [None, pa.py_buffer(offsets)], children=[values])


def rgba32(rgb) -> np.ndarray:
    """Opaque colours packed as Rerun's ``0xRRGGBBAA`` (uint32), shape (...,), from uint8 RGB (..., 3)."""
    c = np.asarray(rgb, dtype=np.uint32)
    return (c[..., 0] << 24) | (c[..., 1] << 16) | (c[..., 2] << 8) | np.uint32(255)


class _RowSet(NamedTuple):
    """Rows of a batch that hold values (the others are null), in the forms an Arrow list column needs."""

    bits: pa.Buffer | None
    """Validity bitmap (little-endian bit order); None when every row holds values."""
    null_count: int
    valid: np.ndarray
    """Bool mask, shape (n_rows,)."""
    before: np.ndarray
    """Valid rows before each row, shape (n_rows + 1,), int32: the offsets of one value per valid row."""


class ColumnBatch:
    """Component columns of several entities on one index, sent as one record batch.

    ``times`` [s] on ``timeline`` give one row per time point; None gives one static row.
    """

    def __init__(self, times: np.ndarray | None = None, timeline: str = "sim_time"):
        self.timeline = None if times is None else timeline
        self.n_rows = 1 if times is None else len(times)
        self._fields: list[pa.Field] = []
        self._arrays: list[pa.Array] = []
        self._row_sets: dict[object, tuple[object, _RowSet]] = {}
        if times is not None:
            ns = np.round(np.asarray(times, dtype=float) * 1e9).astype("timedelta64[ns]")
            self._fields.append(
                pa.field(
                    timeline,
                    pa.duration("ns"),
                    metadata={"rerun:kind": "index", "rerun:index_name": timeline},
                )
            )
            self._arrays.append(pa.array(ns, type=pa.duration("ns")))

    def _rows(self, rows) -> _RowSet:
        """The row set of ``rows`` (None: every row; :data:`FIRST_ROW`), worked out once per batch.

        Columns of one batch share a few row sets (the logged states', the first row), and building
        a validity bitmap costs several numpy calls. A ``rows`` object is recognised by identity (it
        is kept alive with its row set), so the same array passed again costs one lookup.
        """
        key = rows if rows is None or rows is FIRST_ROW else id(rows)
        hit = self._row_sets.get(key)
        if hit is not None and hit[0] is rows:
            return hit[1]
        valid = np.zeros(self.n_rows, dtype=bool)
        if rows is None:
            valid[:] = True
        elif rows is FIRST_ROW:
            valid[0] = True
        else:
            index = np.asarray(rows, dtype=np.int64)
            if index.size and (index[0] < 0 or index[-1] >= self.n_rows or np.any(np.diff(index) <= 0)):
                raise ValueError(
                    f"rows must be distinct, ascending and below {self.n_rows}, got {index.tolist()}"
                )
            valid[index] = True
        n = int(np.count_nonzero(valid))
        before = np.zeros(self.n_rows + 1, dtype=np.int32)
        np.cumsum(valid, out=before[1:])
        bits = pa.py_buffer(np.packbits(valid, bitorder="little")) if n < self.n_rows else None
        out = _RowSet(bits, self.n_rows - n, valid, before)
        self._row_sets[key] = (rows, out)
        return out

    def add(self, entity: str, archetype: str, field: str, items, lengths=None, rows=None) -> None:
        """Add ``rr.{archetype}``'s ``field`` of ``entity``: all rows' values in ``items`` (first axis).

        ``rows``: the rows (time points) that hold values, ascending; the others are null (nothing
        logged there: a latest-at query finds the row before). Default: every row. ``lengths``: how
        many values each of these rows holds (an int: as many in each); default: all of them in the
        one static row, or one per row on a timeline.
        """
        column, t, levels = _field(entity, archetype, field)
        rs = self._rows(rows)
        values = _items(levels, items)
        if lengths is None:
            lengths = len(values) if self.timeline is None else 1
        if isinstance(lengths, int | np.integer):  # as many values in every valid row
            offsets = rs.before if lengths == 1 else rs.before * np.int32(lengths)
        else:
            n = self.n_rows - rs.null_count
            if len(lengths) != n:
                raise ValueError(f"{entity} {field}: {len(lengths)} rows of values for {n} rows")
            per_row = np.zeros(self.n_rows, dtype=np.int32)
            per_row[rs.valid] = lengths
            offsets = np.zeros(self.n_rows + 1, dtype=np.int32)
            np.cumsum(per_row, out=offsets[1:])
        if len(values) != offsets[-1]:
            raise ValueError(f"{entity} {field}: {len(values)} values for rows of {offsets[-1]} in all")
        self._arrays.append(
            pa.Array.from_buffers(
                t, self.n_rows, [rs.bits, pa.py_buffer(offsets)], null_count=rs.null_count, children=[values]
            )
        )
        self._fields.append(column)

    def add_once(self, entity: str, archetype: str, field: str, items) -> None:
        """Add ``field`` of ``entity`` at the first row only (null after it); the one row if static.

        What never changes over a rollout (meshes, colours, names, the outcome) then shares the
        entity's chunk of per-step data, and the static parts one record batch with it: each chunk
        and each batch costs Rerun ~0.2 ms of CPU, and a latest-at query from the first time point on
        finds the values all the same.
        """
        self.add(entity, archetype, field, items, len(items), rows=FIRST_ROW)

    def send(self, rec: rr.RecordingStream) -> None:
        """Send every column added (one chunk per entity); nothing if none were."""
        if len(self._arrays) > (self.timeline is not None):
            batch = pa.RecordBatch.from_arrays(self._arrays, schema=pa.schema(self._fields))
            rec.send_record_batch(batch, index=self.timeline)

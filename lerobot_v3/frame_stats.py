"""Exact statistics over every frame of a LeRobot set, in memory that does not grow with the set.

    stats = FrameStats({key: stat names})   # the stats.json entries to fill, e.g. from a shard's
    stats.add(table)                        # the frames in order, as pyarrow tables of any size
    stats.result(reread)                    # reread(keys): the same frames again -> {key: {name: [...]}}
    write_frame_stats(root)                 # root/meta/stats.json over root's data files

LeRobot 0.6.1's aggregate_datasets and recompute_stats combine per-episode statistics, and their
q01..q99 are averages of per-episode quantiles (lerobot issue 4156), not quantiles of the data.
Here, per dimension of each feature, in float64:

- count, min, max: exact.
- mean, std: from blocks of BLOCK frames, combined in order with Chan, Golub and LeVeque's update,
  so the bits depend on the frames alone, never on how they were cut into tables (within 1e-12 of
  numpy's over the whole column).
- q01..q99: numpy's `quantile` (method "linear"), bit for bit, without holding the column. Each
  quantile interpolates between two order statistics (ranks k and k + 1 of the sorted column), and
  those are found by counting: a value's float64 bits, made order-preserving, are a 64-bit key;
  add() counts every key's top BITS bits (65,536 bins per dimension); each later pass over the
  frames reads out the values of a bin that holds at most COLLECT of them, or counts the next
  REFINE bits of a larger one (a bin whose values are all equal is done at once). At 10^4 demos
  (321 k frames) one more pass finishes, at 10^5 two.

Memory: the bins (0.5 MB a dimension), one table of frames at a time (one feature at a time when
reading back), and the values of the bins read out (at most COLLECT each): none of it grows with
the set. -0.0 is counted as 0.0.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

BLOCK = 2**16  # frames per block of the mean/std update
BITS = 16  # key bits add() counts: 2**16 bins of 8 bytes per dimension
REFINE = 8  # key bits a later pass counts in a bin too large to read out (2 KB per bin)
COLLECT = 2**14  # a bin of at most this many values is read out and sorted (128 KB)
SIGN = np.uint64(1 << 63)


def matrix(col) -> np.ndarray:
    """A pyarrow column of numbers or fixed-size lists as float64 (frames, dims), -0.0 made 0.0."""
    import pyarrow as pa

    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_list(col.type) or pa.types.is_fixed_size_list(col.type):
        x = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64).reshape(len(col), -1)
    else:
        x = col.to_numpy(zero_copy_only=False).astype(np.float64).reshape(-1, 1)
    x += 0.0  # -0.0 + 0.0 is 0.0: one key for zero
    return x


def keys(x: np.ndarray) -> np.ndarray:
    """float64 values (no NaN) as uint64 keys in the same order: flip all bits of a negative value,
    set the sign bit of a positive one (b ^ (all ones or 0, from the sign) | the sign bit)."""
    b = np.ascontiguousarray(x).view(np.uint64)
    flip = (b.view(np.int64) >> 63).view(np.uint64)  # arithmetic shift: all ones where negative
    flip |= SIGN
    return b ^ flip


def value_of(key: int) -> float:
    """The float64 whose key() is `key`."""
    b = key ^ (1 << 63) if key >> 63 else ~key & (2**64 - 1)
    return float(np.array([b], np.uint64).view(np.float64)[0])


def quantile_names(names) -> dict[str, float]:
    """{"q01": 0.01, ...}: the quantiles among a stats.json entry's names."""
    return {name: float(name[1:]) / 100 for name in names if re.fullmatch(r"q\d\d", name)}


def lerp_quantile(lo: float, hi: float, q: float, n: int) -> float:
    """numpy's linear quantile q of n sorted values whose ranks k and k + 1 (k = floor((n-1)q)) hold
    lo and hi, with numpy's own arithmetic: the same interpolation on the two values alone."""
    h = (n - 1) * q
    return float(np.quantile(np.array([lo, hi]), h - np.floor(h)))


def ranks(q: float, n: int) -> tuple[int, int]:
    """The order statistics numpy's linear quantile q of n values interpolates between."""
    k = int(np.floor((n - 1) * q))
    return k, min(k + 1, n - 1)


class FrameStats:
    """stats.json entries over every frame fed to add(), in order; see the module docstring."""

    def __init__(self, names: dict[str, list[str]]):
        self.names = names  # {feature: its stat names}
        self.n, self.pending, self.buffered = 0, [], 0  # frames counted; tables not yet in a block
        self.min, self.max, self.mean, self.m2, self.bins, self.nan = {}, {}, {}, {}, {}, {}

    def add(self, table) -> None:
        """The next frames (a pyarrow table with the features' columns)."""
        self.pending.append(table)
        self.buffered += table.num_rows
        while self.buffered >= BLOCK:
            self._block(BLOCK)

    def _block(self, rows: int) -> None:
        import pyarrow as pa

        table = pa.concat_tables(self.pending)
        block, rest = table.slice(0, rows), table.slice(rows)
        self.pending, self.buffered = ([rest] if rest.num_rows else []), rest.num_rows
        n, m = self.n, rows
        for key in self.names:
            x = matrix(block.column(key))  # (m, dims)
            mean = x.mean(0)
            m2 = ((x - mean) ** 2).sum(0)
            top = (keys(np.where(np.isnan(x), 0.0, x)) >> (64 - BITS)).astype(np.intp)  # (m, dims) bins
            bins = np.stack([np.bincount(top[:, j], minlength=2**BITS) for j in range(x.shape[1])])
            if not n:
                self.min[key], self.max[key], self.mean[key], self.m2[key] = x.min(0), x.max(0), mean, m2
                self.bins[key], self.nan[key] = bins, np.isnan(x).any(0)
                continue
            delta = mean - self.mean[key]
            self.mean[key] = self.mean[key] + delta * (m / (n + m))
            self.m2[key] = self.m2[key] + m2 + delta**2 * (n * m / (n + m))
            self.min[key] = np.minimum(self.min[key], x.min(0))
            self.max[key] = np.maximum(self.max[key], x.max(0))
            self.bins[key] += bins
            self.nan[key] |= np.isnan(x).any(0)
        self.n += m

    def result(self, reread) -> dict:
        """{feature: {name: list}} for every name of `names`; reread(features) yields the same frames
        again (tables with at least those columns), once per pass the quantiles still need."""
        if self.buffered:
            self._block(self.buffered)
        n, out = self.n, {}
        need = {
            (key, j): {r for q in quantile_names(names).values() for r in ranks(q, n)}
            for key, names in self.names.items()
            for j in range(len(self.min.get(key, ())))
            if not self.nan[key][j]
        }
        found = self._select(need, reread)
        for key, names in self.names.items():
            dims = range(len(self.min[key]))
            got = {
                "min": self.min[key],
                "max": self.max[key],
                "mean": self.mean[key],
                "std": np.sqrt(self.m2[key] / n),
                "count": [n],
            }
            for name, q in quantile_names(names).items():
                pairs = [[found.get((key, j, r), np.nan) for r in ranks(q, n)] for j in dims]
                got[name] = [lerp_quantile(lo, hi, q, n) for lo, hi in pairs]  # NaN where a value is
            out[key] = {name: [v if name == "count" else float(v) for v in got[name]] for name in names}
        return out

    def _select(self, need: dict, reread) -> dict:
        """{(feature, dim, rank): value} for the ranks in `need` ({(feature, dim): ranks})."""
        found, bins = {}, {}  # bins: (feature, dim, bits, prefix) -> (values in it, {rank: rank in it})
        for (key, j), rs in need.items():
            self._place(bins, key, j, BITS, 0, self.bins[key][j], {r: r for r in rs})
        while bins:
            for b in [b for b in bins if b[2] == 64]:  # a full key: one value
                found |= {(b[0], b[1], r): value_of(b[3]) for r in bins.pop(b)[1]}
            small = {b: [] for b, (count, _) in bins.items() if count <= COLLECT}  # values read out
            big = {b: [np.zeros(2**REFINE, np.int64), np.inf, -np.inf] for b in bins if b not in small}
            features = sorted({b[0] for b in bins})
            for table in reread(features) if bins else ():
                for key in features:  # one feature's numbers at a time: (rows, dims) float64
                    x = matrix(table.column(key))
                    k = {j: keys(x[:, j]) for j in {b[1] for b in bins if b[0] == key}}
                    for b in (b for b in bins if b[0] == key):
                        _, j, bits, prefix = b
                        inside = (k[j] >> (64 - bits)) == prefix
                        if b in small:
                            small[b].append(x[inside, j])
                        elif inside.any():  # counts of the next REFINE bits, the bin's min and max
                            sub = (k[j][inside] >> (64 - bits - REFINE)) & (2**REFINE - 1)
                            v = x[inside, j]
                            big[b][0] += np.bincount(sub.astype(np.intp), minlength=2**REFINE)
                            big[b][1:] = min(big[b][1], v.min()), max(big[b][2], v.max())
            nxt = {}
            for b, (_, within) in bins.items():
                key, j, bits, prefix = b
                if b in small:
                    values = np.sort(np.concatenate(small[b]))
                    found |= {(key, j, r): float(values[i]) for r, i in within.items()}
                elif big[b][1] == big[b][2]:  # every value in the bin is the same
                    found |= {(key, j, r): float(big[b][1]) for r in within}
                else:
                    self._place(nxt, key, j, bits + REFINE, prefix, big[b][0], within)
            bins = nxt
        return found

    @staticmethod
    def _place(bins: dict, key: str, j: int, bits: int, prefix: int, counts, within: dict) -> None:
        """Each rank of `within` ({rank: rank among the values under `prefix`}) into the bin of
        `counts` (the counts of the key bits after prefix, up to `bits`) that holds it."""
        cum = np.cumsum(counts)
        step = int(np.log2(len(counts)))
        for r, i in within.items():
            sub = int(np.searchsorted(cum, i, side="right"))
            b = (key, j, bits, (prefix << step) | sub)
            bins.setdefault(b, (int(counts[sub]), {}))[1][r] = i - (int(cum[sub - 1]) if sub else 0)


def row_groups(files, columns):
    """The frames of parquet `files` in order, one row group at a time, `columns` only."""
    import pyarrow.parquet as pq

    for f in files:
        pf = pq.ParquetFile(f)
        for i in range(pf.num_row_groups):
            yield pf.read_row_group(i, columns=columns)


def write_frame_stats(root: Path, template: dict | None = None, stats: FrameStats | None = None) -> None:
    """Write root/meta/stats.json with every numeric feature's stats over all frames: the entries of
    `template` (the stats.json there when None), each key that is a data column recomputed (others
    kept as they are). `stats`: a FrameStats already fed root's frames (the merge feeds it while it
    writes them); otherwise one pass over the data files feeds it here. Keys sorted."""
    import pyarrow.parquet as pq

    root = Path(root)
    path = root / "meta" / "stats.json"
    old = json.loads(path.read_text()) if template is None else template
    files = sorted((root / "data").rglob("*.parquet"))
    columns = set(pq.read_schema(files[0]).names)
    if stats is None:
        stats = FrameStats({k: sorted(st) for k, st in old.items() if k in columns})
        for table in row_groups(files, list(stats.names)):
            stats.add(table)
    new = {k: st for k, st in old.items() if k not in stats.names}
    new |= stats.result(lambda keys: row_groups(files, keys))
    path.write_text(json.dumps(new, indent=4, sort_keys=True, ensure_ascii=False))

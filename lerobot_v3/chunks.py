"""The v3 file layout's one rule: where the next block of rows goes, data/chunk-CCC/file-FFF.parquet.

A file takes blocks of rows until the next block would pass its row limit; then the next file
begins, and after chunks_size files the next chunk (LeRobot's update_chunk_file_indices). A block
(an episode, or a slice of the episodes table) never straddles two files. The writer and the merge
both place their rows here; each turns its byte limit into rows as LeRobot does for that file
(rows_below for the writer's data files, rows_within for the merge and the episodes table).
"""

from __future__ import annotations

from lerobot_v3.hub import hub_offline

__all__ = ["ChunkRoller", "rows_below", "rows_within"]


def rows_within(limit_bytes: float, row_bytes: float) -> int:
    """The most rows of `row_bytes` each whose total stays within `limit_bytes` (at least 1)."""
    return max(1, int(limit_bytes // max(1, row_bytes)))


def rows_below(limit_bytes: int, row_bytes: int) -> int:
    """The most rows of `row_bytes` each whose total stays below `limit_bytes`: LeRobot's data-file rule
    (a new file once rows x row_bytes >= the limit), for integer sizes."""
    return -(-limit_bytes // row_bytes) - 1


class ChunkRoller:
    """(chunk, file) for each block of rows placed in order, at most `limit_rows` rows a file (a block
    larger than that gets a file of its own)."""

    def __init__(self, limit_rows: int, chunks_size: int) -> None:
        self.limit_rows, self.chunks_size = limit_rows, chunks_size
        self.chunk = self.file = self.placed = 0  # rows placed in the current file

    def place(self, rows: int) -> tuple[int, int]:
        """Where the next block of `rows` rows goes, starting a new file if it would not fit."""
        if self.placed and self.placed + rows > self.limit_rows:
            hub_offline()
            from lerobot.datasets.utils import update_chunk_file_indices

            self.chunk, self.file = update_chunk_file_indices(self.chunk, self.file, self.chunks_size)
            self.placed = 0
        self.placed += rows
        return self.chunk, self.file

"""Append-only results: one JSON object per line, flushed and fsync'ed per row.

A sweep killed at any moment (Ctrl-C, kill -9) leaves at most one torn last
line; opening the store cuts it off, so a resumed sweep finds every finished
row exactly once and redoes only what is missing. Images are written next to
it under temporary names and renamed (images.atomic_path), and a run's row is
appended only after its image exists, so a row never points at a missing file.

A progressive run (experiment/execution/progressive.py) is one row too, with its checkpoints inside it
(``checkpoints``: spp, elapsed time, metrics and image after each pass), appended only after
every checkpoint image exists: a run killed halfway leaves no row and is rendered again, whole.
Readers (the report, results.csv) see each checkpoint as a run row of its own point
(``current_runs``); the runner's resume and retirement work on the stored rows (``stored_runs``).
"""
from __future__ import annotations

import json
import os

SCHEMA_VERSION = 1


class ResultStore:
    def __init__(self, folder: str):
        self.folder = folder
        self.path = os.path.join(folder, "results.jsonl")
        os.makedirs(folder, exist_ok=True)
        self.rows = self._load()
        self._current: tuple[int, list[dict]] | None = None    # current_runs() for len(rows)
        self._remove_stale_temporaries()

    def _remove_stale_temporaries(self) -> None:
        """A kill -9 between creating an image's temporary file and renaming it leaves the
        temporary behind (no row names it); a resumed sweep removes it."""
        folder = os.path.join(self.folder, "images")
        if os.path.isdir(folder):
            for name in os.listdir(folder):
                if name.startswith(".") and ".tmp" in name:
                    os.unlink(os.path.join(folder, name))

    def _load(self) -> list[dict]:
        if not os.path.exists(self.path):
            return []
        rows, keep = [], 0
        with open(self.path, "rb") as f:
            data = f.read()
        for line in data.split(b"\n"):
            if not line.strip():
                keep += len(line) + 1
                continue
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                break                           # a torn line: only the last one can be
            keep += len(line) + 1
        keep = min(keep, len(data))
        if keep < len(data):                    # cut the torn tail before appending again
            with open(self.path, "r+b") as f:
                f.truncate(keep)
        return rows

    def append(self, row: dict) -> None:
        row = {"schema": SCHEMA_VERSION, **row}
        line = (json.dumps(row, sort_keys=True, allow_nan=True) + "\n").encode()
        with open(self.path, "ab") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
        self.rows.append(row)

    def of_kind(self, kind: str) -> list[dict]:
        return [r for r in self.rows if r.get("kind") == kind]

    def stored_runs(self) -> list[dict]:
        """Stored run rows in force: the latest row of each (point, seed), unless a later
        ``superseded`` row retired it (its identity no longer matched the sweep's).
        Superseded rows stay in the file; resumes read only these."""
        if self._current is not None and self._current[0] == len(self.rows):
            return list(self._current[1])          # rows only grow: same length, same answer
        current: dict[tuple[str, int], dict] = {}
        for row in self.rows:
            kind = row.get("kind")
            if kind == "run":
                current[(row["point"], row["seed"])] = row
            elif kind == "superseded":
                held = current.get((row["point"], row["seed"]))
                if held is not None and held.get("identity_hash") == row.get("identity_hash"):
                    del current[(row["point"], row["seed"])]
        self._current = (len(self.rows), list(current.values()))
        return list(self._current[1])

    def current_runs(self) -> list[dict]:
        """Run rows in force as reports read them: ``stored_runs``, each progressive run
        replaced by one row per checkpoint that stands for a point (``checkpoint_rows``)."""
        return [r for row in self.stored_runs() for r in checkpoint_rows(row)]

    def done_runs(self) -> dict[tuple[str, int], str | None]:
        """(point, seed) -> identity hash of the stored run in force (None for rows stored
        before run identities existed)."""
        return {(r["point"], r["seed"]): r.get("identity_hash") for r in self.stored_runs()}

    def image_path(self, point_id: str, seed: int, identity_hash: str | None = None,
                   checkpoint_spp: int | None = None, attempt: int = 1) -> str:
        """Where a run's image goes; runs of another identity get their own file, so the image
        of a superseded run is never overwritten. A progressive run's checkpoints add their spp;
        a render that replaces stored ones of its identity (``attempt`` > 1: a budget point
        rendered again) adds its attempt, so the row in force keeps its file until replaced."""
        tag = f"__{identity_hash[:8]}" if identity_hash else ""
        at = f"__at{checkpoint_spp}" if checkpoint_spp is not None else ""
        again = f"__try{attempt}" if attempt > 1 else ""
        return os.path.join(self.folder, "images",
                            point_id.replace("/", "__") + f"__seed{seed}{tag}{again}{at}.exr")


def checkpoint_rows(row: dict) -> list[dict]:
    """A stored run as report rows: itself, or for a progressive run one row per checkpoint
    that names a point (``point``: its spp's ladder point, or the budget point for a budget's
    last pass), with the run's fields and the checkpoint's own (spp, elapsed wall_s, metrics,
    image) and ``progressive_run``, the stored run's point."""
    checkpoints = row.get("checkpoints")
    if not checkpoints:
        return [row]
    base = {k: v for k, v in row.items() if k != "checkpoints"}
    return [{**base, **cp, "progressive_run": row["point"]} for cp in checkpoints if cp.get("point")]

"""The tidy results of every study: one row per backend, run, repeat and frame, and one reducer.

Rows are written as they are measured into `results.partial.csv`, flushed after every repeat,
and the file is renamed `results.csv` once the study has run everything: an interrupted run
(Ctrl-C, SIGKILL, a full disk) keeps every repeat it finished. `--resume` reopens the file, drops
a torn last record (what a full disk or a kill in mid-write leaves) and the rows of runs that had
not finished, saying so, and the study measures only what is missing. A run that fails (crash,
timeout, error) leaves one row with its status, so the tidy data holds every outcome.

`summarise` is the one reduction from rows to one line per group (backend, run, size...) that
every table, figure and report uses.
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from own.common import LEFT_OUT

from .cli import NO_SPACE, CliError

COLUMNS = [
    "backend", "params", "experiment", "label", "scene", "dist", "n", "dim", "radius_min", "radius_max", "speed", "seed",
    "repeat", "frame", "t_update_s", "t_pairs_s", "t_narrow_s", "t_total_s", "t_engine_broadphase_s", "candidates",
    "true_pairs", "missed", "false_positives", "box_pairs", "box_missed", "reports", "t_setup_s", "status", "stats",
    "tunneled", "peak_rss_mb", "host", "cpu", "job", "t_compile_s", "shape", "t_queries_s",
]
# Columns added since the first version, with the value every earlier row means (dim: circles;
# compilation: not measured apart, so inside the setup; shape: circles and spheres; queries: none
# asked). A frame's queries (studies/lib/query_runs.py) are part of its total.
ADDED_COLUMNS = {"dim": 2, "t_compile_s": None, "shape": "balls", "t_queries_s": None}
STAGES = ["update", "pairs", "narrow", "total"]
WORKER_DIED = "failed: the worker running it died"  # the status of a job no worker lived through
PARTIAL, FINAL = "results.partial.csv", "results.csv"


def complete_length(data: bytes) -> int:
    """Bytes of `data` up to the end of its last complete CSV record: a newline outside quotes
    (quoted fields, such as the stats column, may hold commas and doubled quotes)."""
    end = len(data)
    while end > 0:
        newline = data.rfind(b"\n", 0, end)
        if newline < 0:
            return 0
        if data.count(b'"', 0, newline) % 2 == 0:
            return newline + 1
        end = newline
    return 0


class RowWriter:
    """Appends rows to `DIR/results.partial.csv`, flushed per call; see the module docstring.

    `done` maps the job key of every finished run found on resume to its rows.
    """

    def __init__(self, folder: Path, resume: bool = False, columns: list[str] = COLUMNS) -> None:
        self.folder, self.columns = Path(folder), columns
        self.path = self.folder / PARTIAL
        self.done: dict[str, list[dict[str, Any]]] = {}
        kept = self._reopen() if resume else None
        if kept is None:
            if (self.folder / FINAL).exists() or self.path.exists():
                print(f"note: replacing the rows in {self.folder} (use --resume to continue them)", file=sys.stderr)
            (self.folder / FINAL).unlink(missing_ok=True)
            self._fh = self._open("w")
            self._writer = csv.DictWriter(self._fh, fieldnames=columns, extrasaction="ignore")
            self._write(lambda: self._writer.writeheader())
        else:
            self._fh = self._open("a")
            self._writer = csv.DictWriter(self._fh, fieldnames=columns, extrasaction="ignore")
        self.written = 0

    def _open(self, mode: str):
        try:
            return open(self.path, mode, newline="")
        except OSError as exc:
            raise CliError(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def _reopen(self) -> int | None:
        """Continue the rows of an earlier run (its partial file, or its finished one); None if none."""
        source = self.path if self.path.exists() else self.folder / FINAL
        if not source.exists():
            print(f"note: no earlier rows in {self.folder}; starting afresh", file=sys.stderr)
            return None
        by_job, unfinished, notes = load_runs(source, self.columns)
        self.done = {k: [typed(r) for r in rs] for k, rs in by_job.items() if k not in unfinished}
        # Rewrite the kept rows through a temporary file, so a failure here loses nothing.
        tmp = self.path.with_suffix(".tmp")
        with open(tmp, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=self.columns)
            writer.writeheader()
            writer.writerows(r for k, rs in by_job.items() if k not in unfinished for r in rs)
        os.replace(tmp, self.path)
        if source != self.path:
            source.unlink()
        kept = sum(map(len, self.done.values()))
        print(f"resuming {self.folder}: {kept} rows of {len(self.done)} finished runs kept"
              + (f"; {'; '.join(notes)}" if notes else ""), file=sys.stderr)
        return kept

    def _write(self, action) -> None:
        """Run a write and flush it; on a full disk, cut the file back to its last whole record
        and stop the study in one line."""
        before = self._fh.tell()
        try:
            action()
            self._fh.flush()
        except OSError as exc:
            if exc.errno not in NO_SPACE:
                raise
            self._abandon(before)
            raise CliError(f"{exc.strerror} writing {self.path}: the rows written before are intact; free some "
                           f"space and rerun with --resume --out {self.folder}") from None

    def _abandon(self, size: int) -> None:
        try:
            self._fh.close()
        except OSError:
            pass  # its buffer could not be written either; what is on disk is cut below
        with open(self.path, "r+b") as fh:
            fh.truncate(size)
        self._fh = None

    def write(self, rows: Iterable[dict[str, Any]], fixed: dict[str, Any] | None = None) -> None:
        rows = list(rows)
        self._write(lambda: self._writer.writerows({**(fixed or {}), **r} for r in rows))
        self.written += len(rows)

    def finish(self) -> Path:
        """Everything ran: close and rename to results.csv."""
        self.close()
        final = self.folder / FINAL
        os.replace(self.path, final)
        return final

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


Runs = dict[str, list[dict[str, Any]]]  # job key -> its rows


def load_runs(source: Path, columns: list[str] = COLUMNS) -> tuple[Runs, set[str], list[str]]:
    """The rows of a results file by job key, the keys of jobs that had not finished, and notes on
    what was left out (a torn last record, an incomplete one, unfinished runs)."""
    data = source.read_bytes()
    cut = complete_length(data)
    notes = []
    if cut < len(data):
        notes.append(f"dropped a torn last record ({len(data) - cut} bytes)")
    parsed = list(csv.reader(io.StringIO(data[:cut].decode("utf-8", errors="replace"), newline="")))
    if not parsed:  # an empty file (a full disk during the header's write): nothing to keep
        notes.append(f"{source.name} was empty")
        return {}, set(), notes
    header, *records = parsed
    # An earlier version's file may lack columns added since (they read as empty), never hold others.
    if not set(header) <= set(columns) or "job" not in header:
        raise CliError(f"{source} has other columns than this version writes; resume into a new --out")
    if records and len(records[-1]) != len(header):
        notes.append("dropped an incomplete last record")
        records.pop()
    by_job: dict[str, list[dict[str, str]]] = {}
    torn = 0
    for record in records:
        if len(record) == len(header):
            row = dict(zip(header, record))
            by_job.setdefault(row["job"], []).append(row)
        else:
            torn += 1
    if torn:  # records broken in the middle of the file: their runs are unfinished, measured again
        notes.append(f"dropped {torn} broken record(s) in the middle of the file")
    unfinished = {k for k, rs in by_job.items() if not finished(k, rs)}
    if unfinished:
        notes.append(f"dropped the rows of {len(unfinished)} unfinished run(s); they are measured again")
    return by_job, unfinished, notes


def cpu_models_note(rows: pd.DataFrame) -> str:
    """A warning when the rows were timed on more than one CPU model (a cluster of unlike machines):
    a ratio between backends timed on different models compares the machines too. "" otherwise."""
    if "cpu" not in rows or rows.cpu.dropna().nunique() <= 1:
        return ""
    models = "; ".join(f"{cpu}: {', '.join(sorted(d.backend.unique()))}"
                       for cpu, d in rows.dropna(subset=["cpu"]).groupby("cpu"))
    return (f"NOTE: these timings come from {rows.cpu.dropna().nunique()} CPU models ({models}); a ratio between "
            "backends timed on different models compares the machines as well as the backends")


def left_out_note(rows: pd.DataFrame) -> str:
    """Which backends left out which parts of a frame for this scene (own.common.LEFT_OUT), as
    their counters said in any timed frame; "" where none did."""
    backends: dict[str, set[str]] = {}
    for backend, stats in rows.loc[rows.status == "ok", ["backend", "stats"]].dropna().itertuples(index=False):
        for key in json.loads(stats):
            if key in LEFT_OUT:
                backends.setdefault(key, set()).add(backend)
    return "; ".join(f"left out {LEFT_OUT[key]}: {', '.join(sorted(backends[key]))}" for key in LEFT_OUT
                     if key in backends)


def stored_runs(folder: Path, columns: list[str] = COLUMNS) -> dict[str, list[dict[str, Any]]]:
    """The finished runs of a study's folder by job key, read-only (for --report-only); `columns`:
    those its rows were written with."""
    folder = Path(folder)
    source = folder / FINAL if (folder / FINAL).exists() else folder / PARTIAL
    if not source.exists():
        raise CliError(f"{folder} holds no {FINAL} or {PARTIAL} to report on")
    by_job, unfinished, _ = load_runs(source, columns)
    return {k: [typed(r) for r in rs] for k, rs in by_job.items() if k not in unfinished}


def finished(key: str, rows: list[dict[str, Any]]) -> bool:
    """Whether a run's rows are all it will write: its last row is a failure, or the last frame of
    its last repeat (the key records both counts)."""
    last = rows[-1]
    if last["status"] != "ok":  # a failure is its outcome; not a worker's death, which --resume tries again
        return not str(last["status"]).startswith(WORKER_DIED)
    planned = json.loads(key)
    # Every row is there too: a record broken in the middle of the file loses one of them.
    return _int(last["repeat"]) == planned["repeats"] - 1 and _int(last["frame"]) == planned["frames"] \
        and len(rows) == planned["repeats"] * planned["frames"]


def _int(text: Any) -> int:
    try:
        return int(float(text))
    except (TypeError, ValueError):
        return -1


INTEGERS = {"n", "seed", "repeat", "frame", "candidates", "true_pairs", "missed", "false_positives", "box_pairs",
            "box_missed", "tunneled"}
FLOATS = {"radius_min", "radius_max", "speed", "peak_rss_mb"} | {c for c in COLUMNS if c.startswith("t_")}
QUERY_COUNTS = ("_found", "_missed", "_wrong", "_extra")  # a query set's counts (studies/lib/query_runs.py)


def typed(row: dict[str, str]) -> dict[str, Any]:
    """A row read back from the CSV as the harness wrote it: numbers as numbers, empty fields None."""
    out: dict[str, Any] = {}
    for key, value in row.items():
        if value == "":
            out[key] = None
        elif key in INTEGERS or key.endswith(QUERY_COUNTS):
            out[key] = int(float(value))
        elif key in FLOATS or (key.startswith("t_") and key.endswith("_s")):  # a query set's time too
            out[key] = float(value)
        else:
            out[key] = value
    return out


def read_rows(folder: Path) -> tuple[pd.DataFrame, bool]:
    """The rows of a study's folder and whether the run finished (results.csv) or not (only
    results.partial.csv: an interrupted run, whose torn last record, if any, is left out)."""
    folder = Path(folder)
    final, partial = folder / FINAL, folder / PARTIAL
    if final.exists():
        return _checked(_read_csv(final.read_bytes(), final), final), True
    if partial.exists():
        data = partial.read_bytes()
        return _checked(_read_csv(data[:complete_length(data)], partial), partial), False
    raise CliError(f"{folder} holds no {FINAL} or {PARTIAL} to report on")


def _read_csv(data: bytes, path: Path) -> pd.DataFrame:
    """The rows of a results file's bytes; an empty file is one line (pandas raises EmptyDataError)."""
    if not data.strip():
        raise CliError(f"{path} is empty: nothing to report (rerun the study, or continue it with --resume --out "
                       f"{path.parent})")
    return pd.read_csv(io.BytesIO(data))


def _checked(rows: pd.DataFrame, path: Path) -> pd.DataFrame:
    """The rows, if the file has a study's columns; else one clear line naming what it lacks.
    Columns added since an earlier version's file take the value its rows meant."""
    for column, value in ADDED_COLUMNS.items():
        if column not in rows.columns:
            rows[column] = value
    lacking = [c for c in COLUMNS if c not in rows.columns]
    if lacking:
        raise CliError(f"{path} is not a study's rows: it lacks the columns {', '.join(lacking[:5])}"
                       + (f" and {len(lacking) - 5} more" if len(lacking) > 5 else ""))
    if rows.empty:
        raise CliError(f"{path} holds no rows yet: nothing to report (continue the run with --resume --out "
                       f"{path.parent})")
    return rows


def _iqr(x: pd.Series) -> float:
    return float(x.quantile(0.75) - x.quantile(0.25))


def summarise(rows: pd.DataFrame, by: list[str], first: Iterable[str] = (), stats: bool = False) -> pd.DataFrame:
    """One line per group of `by` (e.g. ["backend"], or ["dist", "backend", "n"]), indexed by it.

    Over the group's "ok" rows: the median and interquartile range of each stage in ms
    (`update_ms`, `update_iqr_ms`, ... `total_ms`), the quartiles of the total, `low_ms` and
    `high_ms` (the fastest and slowest repeat's median total), `run_ms` (the median over repeats of a
    repeat's mean total: a frame's cost over a run) with `run_low_ms` and `run_high_ms`, medians of the pair counts, the
    mean false positives and candidates beyond those promised per frame (`extra_per_frame`),
    candidates per true pair over the verified frames (`verified` counts them), misses summed
    (and `contacts`, the true pairs summed; `worst_missed_share`, the worst frame's missed share) (`box_missed` stays empty for backends
    that report contacts), the slowest setup, the peak memory, the tunneling count, and with
    `stats`, the median of each of the backend's counters (`stat_<name>`). `status` is "ok" or
    the group's last other status; `partial` says that a group stopped early but kept rows.
    Groups without any "ok" row are kept, with empty times. `first` columns are carried over.
    """
    by, first = list(by), [c for c in first if c not in by]
    if rows.empty:
        return pd.DataFrame(columns=by).set_index(by)
    status = rows["status"].fillna("")
    ok = rows[status == "ok"]
    g = ok.groupby(by, sort=False, dropna=False)
    table = g[first + ["reports", "params"]].first()
    table["frames"] = g.size()
    for stage in STAGES:
        ms = ok[f"t_{stage}_s"] * 1e3
        table[f"{stage}_ms"] = ms.groupby([ok[c] for c in by], sort=False, dropna=False).median()
        table[f"{stage}_iqr_ms"] = ms.groupby([ok[c] for c in by], sort=False, dropna=False).agg(_iqr)
    total = ok.t_total_s * 1e3
    grouped_total = total.groupby([ok[c] for c in by], sort=False, dropna=False)
    table["q25_ms"], table["q75_ms"] = grouped_total.quantile(0.25), grouped_total.quantile(0.75)
    # The engine's own measure of its broad phase, where it has one (empty otherwise).
    engine = ok["t_engine_broadphase_s"] * 1e3
    table["engine_broadphase_ms"] = engine.groupby([ok[c] for c in by], sort=False, dropna=False).median()
    by_repeat = total.groupby([ok[c] for c in by] + [ok["repeat"]], sort=False, dropna=False)
    repeat_medians = by_repeat.median().groupby(level=list(range(len(by))), sort=False, dropna=False)
    table["low_ms"], table["high_ms"] = repeat_medians.min(), repeat_medians.max()
    # What a frame costs over a run, work done once in many frames included (a Verlet list's
    # rebuild, in a minority of frames, is outside the median frame): each repeat's mean frame.
    repeat_means = by_repeat.mean().groupby(level=list(range(len(by))), sort=False, dropna=False)
    table["run_ms"] = repeat_means.median()
    table["run_low_ms"], table["run_high_ms"] = repeat_means.min(), repeat_means.max()
    for col in ("candidates", "true_pairs", "box_pairs"):
        table[col] = g[col].median()
    table["false_positives"] = g["false_positives"].mean()
    # Candidates beyond what the backend promises (every overlapping box, or every contact).
    promised = ok["box_pairs"].where(ok["reports"] == "boxes", ok["true_pairs"])
    table["extra_per_frame"] = (ok["candidates"] - promised).groupby([ok[c] for c in by], sort=False,
                                                                        dropna=False).mean()
    # Over the verified frames (a study may verify a sample of them): their candidates and pairs.
    verified = ok["true_pairs"].notna()
    table["verified"] = verified.groupby([ok[c] for c in by], sort=False, dropna=False).sum()
    true = g["true_pairs"].sum()
    candidates = ok["candidates"].where(verified).groupby([ok[c] for c in by], sort=False, dropna=False).sum()
    table["cand_per_true"] = candidates / true.where(true > 0)
    table["missed"] = g["missed"].sum()
    table["box_missed"] = g["box_missed"].sum(min_count=1)
    table["contacts"] = true  # truly overlapping pairs over the verified frames
    share = (ok["missed"] / ok["true_pairs"].where(ok["true_pairs"] > 0)).fillna(0.0)
    table["worst_missed_share"] = share.groupby([ok[c] for c in by], sort=False, dropna=False).max()
    table["setup_s"] = g["t_setup_s"].max()  # building it and its first frame
    # The first repeat's: compiling or loading our kernels (rows from before it was measured apart: none).
    table["compile_s"] = g["t_compile_s"].max() if "t_compile_s" in ok else np.nan
    table["peak_mb"] = g["peak_rss_mb"].max()
    table["tunneled"] = g["tunneled"].last()
    if stats:
        counters = ok["stats"].fillna("{}").map(json.loads).apply(pd.Series)
        if not counters.empty:
            counters = counters.apply(pd.to_numeric, errors="coerce")
            counters = counters.groupby([ok[c] for c in by], sort=False, dropna=False).median()
            table = table.join(counters.add_prefix("stat_"))
    failed = rows[status != "ok"]
    last_failure = failed.groupby(by, sort=False, dropna=False)["status"].last()
    table["status"] = "ok"
    table["partial"] = False
    if len(last_failure):
        stopped = last_failure.index.intersection(table.index)
        table.loc[stopped, "status"] = last_failure.loc[stopped]
        table.loc[stopped, "partial"] = True
        only_failed = last_failure.index.difference(table.index, sort=False)
        if len(only_failed):
            extra = failed.groupby(by, sort=False, dropna=False)[first + ["reports", "params"]].first().loc[only_failed]
            extra["status"] = last_failure.loc[only_failed]
            extra["partial"] = False
            extra["frames"] = 0
            table = pd.concat([table, extra])
    # In the order the groups first appear in the rows, failed ones included.
    return table.reindex(rows.groupby(by, sort=False, dropna=False).size().index)


def missed_total(table: pd.DataFrame) -> pd.Series:
    """Misses per line of a summary: overlapping circles, plus overlapping boxes for 'boxes' backends."""
    return table["missed"].fillna(0) + table["box_missed"].fillna(0)


def ok_lines(table: pd.DataFrame) -> pd.DataFrame:
    """The summary's lines with measured times."""
    return table[np.isfinite(table["total_ms"].astype(float))] if len(table) else table

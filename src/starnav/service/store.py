"""The service's records: sessions, submissions and their jobs, in SQLite under the data dir.

One submission holds one image or source list and gets one job, numbered alike (nova's
``api/submissions/N`` lists job N). A job is "queued", "solving", "success" or "failure";
a finished job keeps its reason, nova calibration and starnav's solution as JSON, and its
files (input, WCS, new FITS, annotated PNG, result JSON) live in ``DATA/jobs/N/`` under names
the service chooses, never the client's. Every write is one committed transaction, so a
restart loses no finished job (``JobStore.recover`` fails the ones that were solving and
gives back the ones still queued).
"""

from __future__ import annotations

import json
import re
import secrets
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path

SCHEMA = """
CREATE TABLE IF NOT EXISTS sessions (
    key TEXT PRIMARY KEY,
    created REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS jobs (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    kind TEXT NOT NULL,              -- "image" or "xy"
    original_filename TEXT NOT NULL,
    input_name TEXT,                 -- file name in the job's directory (image) or NULL
    request TEXT NOT NULL,           -- the client's JSON (hints), as received
    status TEXT NOT NULL,            -- queued | solving | success | failure
    submitted REAL NOT NULL,
    started REAL,
    finished REAL,
    reason TEXT,
    calibration TEXT,                -- nova's calibration JSON (solved)
    result TEXT,                     -- starnav's JSON of the solve
    owner TEXT,                      -- the session that submitted it (NULL: unknown)
    public INTEGER NOT NULL DEFAULT 1  -- nova's publicly_visible: "y" 1, "n" 0
);
"""
# columns added since the first schema, with their definitions: an older starnav.sqlite gets
# them when it is opened (its jobs: owner unknown, public unless their request said "n")
ADDED_COLUMNS = {"owner": "TEXT", "public": "INTEGER NOT NULL DEFAULT 1"}
STATUSES = ("queued", "solving", "success", "failure")
INTERRUPTED = "interrupted: the server stopped while this job was solving"
SESSION_KEY = re.compile(r"[0-9a-f]{32}")  # new_session's keys
MAX_JOB_ID = 2**63 - 1  # SQLite's largest integer
UNSTORED = "interrupted: the server stopped before the upload was stored"


@dataclass(frozen=True)
class Job:
    """One job's record (times: Unix seconds, None when not reached)."""

    id: int
    kind: str
    original_filename: str
    input_name: str | None
    request: dict
    status: str
    submitted: float
    started: float | None
    finished: float | None
    reason: str | None
    calibration: dict | None
    result: dict | None
    owner: str | None = None
    public: bool = True

    @property
    def done(self) -> bool:
        """Finished: "success" or "failure"."""
        return self.status in ("success", "failure")


class JobStore:
    """The SQLite file ``DATA/starnav.sqlite`` and the job directories ``DATA/jobs/N``."""

    def __init__(self, data_dir: str | Path):
        self.data_dir = Path(data_dir).resolve()
        (self.data_dir / "jobs").mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(
            self.data_dir / "starnav.sqlite", check_same_thread=False, isolation_level=None
        )
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.executescript(SCHEMA)
        self._add_columns()

    def _add_columns(self) -> None:
        """Bring a starnav.sqlite of an older schema up to this one."""
        have = {row[1] for row in self._db.execute("PRAGMA table_info(jobs)")}
        missing = [name for name in ADDED_COLUMNS if name not in have]
        if not missing:
            return
        self._db.execute("BEGIN IMMEDIATE")  # all or nothing: no job public by a crash
        for name in missing:
            self._db.execute(f"ALTER TABLE jobs ADD COLUMN {name} {ADDED_COLUMNS[name]}")
            if name == "public":
                self._db.execute(
                    "UPDATE jobs SET public = 0 "
                    "WHERE json_extract(request, '$.publicly_visible') = 'n'"
                )
        self._db.execute("COMMIT")

    def close(self) -> None:
        """Close the database."""
        self._db.close()

    def _write(self, sql: str, args: tuple = ()) -> sqlite3.Cursor:
        with self._lock:
            return self._db.execute(sql, args)

    def new_session(self) -> str:
        """A new session key (nova's ``api/login``)."""
        key = secrets.token_hex(16)
        self._write("INSERT INTO sessions VALUES (?, ?)", (key, time.time()))
        return key

    def has_session(self, key: object) -> bool:
        """Whether ``key`` was given by ``new_session`` (False for anything not shaped like
        one of its keys, which is never looked up)."""
        if not isinstance(key, str) or not SESSION_KEY.fullmatch(key):
            return False
        with self._lock:
            row = self._db.execute("SELECT 1 FROM sessions WHERE key = ?", (key,)).fetchone()
        return row is not None

    def add_job(
        self,
        kind: str,
        original_filename: str,
        request: dict,
        *,
        owner: str | None = None,
        public: bool = True,
    ) -> int:
        """A queued job submitted by session ``owner`` (``public``: readable by anyone, nova's
        ``publicly_visible``); its directory is made. Returns its number."""
        cur = self._write(
            "INSERT INTO jobs (kind, original_filename, request, status, submitted, owner, "
            "public) VALUES (?, ?, ?, 'queued', ?, ?, ?)",
            (kind, _text(original_filename, printable=True)[:200], json.dumps(request),
             time.time(), owner, int(public)),
        )  # fmt: skip
        job_id = int(cur.lastrowid)
        self.job_dir(job_id).mkdir(parents=True, exist_ok=True)
        return job_id

    def job_dir(self, job_id: int) -> Path:
        """The directory of job ``job_id`` (made by ``add_job``)."""
        return self.data_dir / "jobs" / str(int(job_id))

    def set_input(self, job_id: int, name: str) -> None:
        """Record the name of the job's input file in its directory."""
        self._write("UPDATE jobs SET input_name = ? WHERE id = ?", (name, job_id))

    def start(self, job_id: int) -> None:
        """The job is being solved."""
        self._write(
            "UPDATE jobs SET status = 'solving', started = ? WHERE id = ?", (time.time(), job_id)
        )

    def finish(
        self, job_id: int, solved: bool, reason: str, calibration: dict | None, result: dict | None
    ) -> None:
        """The job's answer (status "success" when ``solved``, else "failure")."""
        self._write(
            "UPDATE jobs SET status = ?, finished = ?, started = COALESCE(started, ?), "
            "reason = ?, calibration = ?, result = ? WHERE id = ?",
            (
                "success" if solved else "failure",
                time.time(),
                time.time(),
                _text(reason),
                None if calibration is None else json.dumps(calibration),
                None if result is None else json.dumps(result),
                job_id,
            ),
        )

    def get(self, job_id: int) -> Job | None:
        """Job ``job_id``, or None when there is none (any integer: one outside SQLite's
        range has none)."""
        if not 0 < job_id <= MAX_JOB_ID:
            return None
        with self._lock:
            row = self._db.execute("SELECT * FROM jobs WHERE id = ?", (int(job_id),)).fetchone()
        return None if row is None else _job(row)

    def job_ids(self, owner: str | None = None) -> list[int]:
        """Every job's number, in order (of session ``owner``'s jobs only, when given)."""
        with self._lock:
            if owner is None:
                return [r[0] for r in self._db.execute("SELECT id FROM jobs ORDER BY id")]
            rows = self._db.execute("SELECT id FROM jobs WHERE owner = ? ORDER BY id", (owner,))
            return [r[0] for r in rows]

    def recover(self) -> list[int]:
        """After a restart: jobs that were solving are failed (``INTERRUPTED``); returns the
        queued ones, to be run again."""
        self._write(
            "UPDATE jobs SET status = 'failure', finished = ?, reason = ? WHERE status = 'solving'",
            (time.time(), INTERRUPTED),
        )
        with self._lock:
            rows = self._db.execute("SELECT id FROM jobs WHERE status = 'queued' ORDER BY id")
            return [r[0] for r in rows]

    def fail_unstored(self) -> list[int]:
        """After a restart: image jobs whose upload was never stored (the server stopped
        between making the job and recording its input) are failed (``UNSTORED``); returns
        their numbers."""
        with self._lock:
            rows = self._db.execute(
                "SELECT id FROM jobs WHERE kind = 'image' AND input_name IS NULL "
                "AND status IN ('queued', 'solving') ORDER BY id"
            )
            ids = [r[0] for r in rows]
        for job_id in ids:
            self.finish(job_id, False, UNSTORED, None, None)
        return ids


def _text(text: str, printable: bool = False) -> str:
    """``text`` as SQLite can store it: a lone surrogate (which UTF-8 cannot encode) as its
    escape; ``printable``: without control and format characters (a NUL, a right-to-left
    mark) too, for a name shown to people."""
    if printable:
        text = "".join(c for c in text if c.isprintable())
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _job(row: tuple) -> Job:
    (id_, kind, name, input_name, request, status, submitted, started, finished, reason, cal,
     result, owner, public) = row  # fmt: skip
    return Job(
        id_,
        kind,
        name,
        input_name,
        json.loads(request),
        status,
        submitted,
        started,
        finished,
        reason,
        None if cal is None else json.loads(cal),
        None if result is None else json.loads(result),
        owner,
        bool(public),
    )

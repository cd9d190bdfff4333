"""Per-run claims: two runners on one experiment share its grid instead of both doing it.

Before a runner starts a run it claims it: ``<experiment>/claims/<run_id>.claim``, a
small JSON file naming the owner (host, pid, the pid's start time, a random token,
when it was claimed). The file is created atomically and exclusively: the owner
line is written to a temporary file, which is then hard-linked onto the claim's
name (``link`` fails when the name exists, like ``open(O_CREAT | O_EXCL)``, and
unlike it the claim is never seen half-written). Exactly one runner gets each run.

A claim is *stale*, and is taken over, when its owner is gone:
- on this host: no process has the owner's pid, or one has it but started at
  another time (the pid was reused);
- on another host (a shared file system): the claim's file was not touched for
  `HEARTBEAT_TIMEOUT` seconds (a live owner touches its claims every
  `HEARTBEAT_EVERY` seconds, `RunClaim.touch`).
Taking over renames the stale file to a private name (one renamer wins), checks
that the file it moved is the stale one it judged (otherwise puts it back) and
claims again. The owner releases a claim when its run is recorded (done or failed)
or when it stops; a runner killed with SIGKILL leaves claims that the next runner
finds stale.
"""

from __future__ import annotations

import json
import os
import secrets
import socket
import time
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

CLAIMS_DIR = "claims"
HEARTBEAT_EVERY = 30.0     # seconds between touches of a live runner's claims
HEARTBEAT_TIMEOUT = 600.0  # seconds without a touch after which another host's claim is stale


def _proc_stat(pid: int) -> list[str] | None:
    """The fields of /proc/<pid>/stat after the command name (state first), None when there
    is no such process or no /proc."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            stat = fh.read()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2:].split()


def process_start(pid: int) -> str | None:
    """The start time of process ``pid`` (clock ticks since boot, from /proc), None
    when no such process exists or /proc is not there."""
    fields = _proc_stat(pid)
    return None if fields is None else fields[19]  # field 22, counted after the command name


def pid_alive(pid: int, start: str | None = None) -> bool:
    """Whether process ``pid`` exists (and, given ``start``, started then). A zombie (exited,
    not yet reaped: an orphaned worker whose reaper is slow) is not alive: it writes nothing more."""
    if os.path.isdir("/proc"):
        fields = _proc_stat(pid)
        if fields is None or fields[0] in ("Z", "X"):
            return False
        return start is None or fields[19] == start
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@dataclass(frozen=True)
class Owner:
    """Who holds a claim."""

    host: str
    pid: int
    start: str | None  # the pid's start time (`process_start`), None where unknown
    token: str         # random: tells two claims of one process apart
    claimed: str       # ISO-8601 local time

    @classmethod
    def me(cls) -> Owner:
        pid = os.getpid()
        return cls(socket.gethostname(), pid, process_start(pid), secrets.token_hex(8),
                   datetime.now().astimezone().isoformat(timespec="seconds"))

    def text(self) -> str:
        return json.dumps({"host": self.host, "pid": self.pid, "start": self.start, "token": self.token,
                           "claimed": self.claimed}, sort_keys=True) + "\n"

    @classmethod
    def parse(cls, text: str) -> Owner | None:
        try:
            data = json.loads(text)
            owner = cls(str(data["host"]), int(data["pid"]), data["start"], str(data["token"]), str(data["claimed"]))
        except (ValueError, KeyError, TypeError, OverflowError, RecursionError):
            return None  # a damaged claim: treated as no owner (stale)
        if owner.pid <= 0 or not (owner.start is None or isinstance(owner.start, str)):
            return None
        return owner

    def gone(self, mtime: float) -> bool:
        """Whether this owner no longer holds its claim (module doc: stale)."""
        if self.host == socket.gethostname():
            return not pid_alive(self.pid, self.start)
        return time.time() - mtime > HEARTBEAT_TIMEOUT


@dataclass(frozen=True)
class RunClaim:
    """A claim this process holds on one run."""

    path: Path
    owner: Owner

    def touch(self) -> None:
        """Heartbeat: mark the claim as live (for runners on other hosts)."""
        try:
            os.utime(self.path)
        except OSError:
            pass

    def release(self) -> None:
        """Remove the claim, if it is still this owner's."""
        if _read(self.path)[0] == self.owner:
            self.path.unlink(missing_ok=True)


def claim_path(folder: str | Path, run_id: str) -> Path:
    return Path(folder) / CLAIMS_DIR / f"{run_id}.claim"


def _read(path: Path) -> tuple[Owner | None, float]:
    try:
        text, mtime = path.read_text(encoding="utf-8"), path.stat().st_mtime
    except (OSError, UnicodeDecodeError):
        return None, 0.0
    return Owner.parse(text), mtime


def try_claim(folder: str | Path, run_id: str) -> RunClaim | None:
    """Claim run ``run_id`` of the experiment in ``folder``; None when a live owner
    holds it (module doc)."""
    path = claim_path(folder, run_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    me = Owner.me()
    for _ in range(5):
        temp = path.with_name(f".{path.name}.{me.pid}.{me.token}.tmp")
        temp.write_text(me.text(), encoding="utf-8")
        try:
            os.link(temp, path)
            return RunClaim(path, me)
        except FileExistsError:
            pass
        finally:
            temp.unlink(missing_ok=True)
        owner, mtime = _read(path)
        if owner is None:
            if mtime == 0.0:
                continue  # released meanwhile: try again
            if time.time() - mtime < HEARTBEAT_TIMEOUT:
                return None  # unreadable but recent: treat it as held
        elif not owner.gone(mtime):
            return None
        # stale: move it out of the way; of several runners doing this, one wins
        grave = path.with_name(f".{path.name}.{me.pid}.{me.token}.stale")
        try:
            os.rename(path, grave)
        except FileNotFoundError:
            continue
        moved, _ = _read(grave)
        if moved != owner:  # a live claim made after our check: put it back
            try:
                os.link(grave, path)
            except FileExistsError:
                pass
            grave.unlink(missing_ok=True)
            return None
        grave.unlink(missing_ok=True)
    return None


def held(folder: str | Path, run_id: str) -> bool:
    """Whether a live owner holds run ``run_id`` of the experiment in ``folder`` (module doc),
    without claiming it: another experiment's runner asks before it runs a run of the same id."""
    owner, mtime = _read(claim_path(folder, run_id))
    if owner is None:  # none, or unreadable: held only while recent, as `try_claim` reads it
        return mtime != 0.0 and time.time() - mtime < HEARTBEAT_TIMEOUT
    return not owner.gone(mtime)


def remove_stale_claim_temps(folder: str | Path) -> None:
    """Delete claim temporaries left by dead processes of this host."""
    claims = Path(folder) / CLAIMS_DIR
    if not claims.is_dir():
        return
    for entry in claims.iterdir():
        parts = entry.name.split(".")
        if entry.name.startswith(".") and len(parts) >= 5 and parts[-3].isdigit() and not pid_alive(int(parts[-3])):
            entry.unlink(missing_ok=True)


__all__ = ["RunClaim", "Owner", "try_claim", "held", "claim_path", "pid_alive", "process_start", "remove_stale_claim_temps",
           "CLAIMS_DIR", "HEARTBEAT_EVERY", "HEARTBEAT_TIMEOUT"]

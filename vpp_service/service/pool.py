"""A pool of workers sharing one rig's frames over Zenoh: membership, ownership, failover.

Every worker of a rig's pool receives every frame of the rig (it subscribes to
``<prefix>/<rig>/in/*`` like a single service) and decides on its own whether a
frame is its share; no worker talks to another and there is no coordinator.

Membership
    Each worker holds a liveliness token ``<prefix>/<rig>/@pool/<worker-id>``
    and watches ``<prefix>/<rig>/@pool/*`` (a liveliness subscriber with
    history, plus one liveliness query at start so the first frame already sees
    the members). A worker that dies (SIGKILL, a lost link) loses its token:
    Zenoh reports it to every other member.
Ownership
    Rendezvous (highest-random-weight) hashing: frame ``seq`` belongs to the live
    member with the highest :func:`weight` ``blake2b(seq, member)``;
    :func:`rendezvous_order` is the full order. It is the same in every process,
    and a member joining or leaving changes the owner only of the frames it
    wins or held: in steady state no frame is processed twice.
Answers
    After its sinks have written a result, a worker announces ``seq`` on
    ``<prefix>/<rig>/@answered`` (a few bytes: :func:`encode_answered`), so the
    others learn which frames were answered without receiving the output maps.
    The outputs themselves carry ``seq`` and ``worker``.
Failover
    A worker keeps a record of every frame it saw but does not own (its owner,
    when it arrived) and, while the frame is fresh (``deadline_s``), the frame
    itself. When a member's token disappears, its unanswered frames go to the
    next member of each frame's rendezvous order: the worker that is now their
    owner processes those still fresh and counts the older ones (or those whose
    image it no longer holds) as ``lost``. Each frame has one successor, so a loss is
    counted once in the pool.
Trust
    Anyone on the network may put an ``@answered`` message or declare an ``@pool`` token.
    So a worker never skips a frame it owns on another's word (an answer for one of its
    frames from any other worker makes a duplicate at most), an answer forgets another
    member's record only when it comes from that frame's owner, and answers from ids that
    hold no token are ignored (``foreign_answers``). Each worker also puts a heartbeat on
    ``@answered`` four times per deadline (at least 1 s). A member that owns a frame older than
    that time and has said nothing (answer or heartbeat) for that long (a peer that only
    declared a token, or a worker process that hangs) is *silent*: it owns no frame until
    it speaks again; its frames still fresh are taken over, the older ones counted
    ``silent_lost`` (until an answer for one of them comes after all).
    A peer that holds a token *and* answers the frames it owns cannot be told apart from a
    worker without its outputs: the router's ACL keeps ``@pool`` and ``@answered`` to the
    workers' identity (``deploy/secure/``). (Forged answers under a member's id can still
    inflate ``duplicates``: that counter cannot tell them from real second answers.)
Duplicates
    A frame answered by two workers (a member that was cut off but kept working,
    a join seen at different times) is counted in ``duplicates`` once per extra
    answer: by each answering worker except the one with the smallest id.
    Consumers drop duplicates by ``seq`` (:class:`vpp_service.transport.reorder.ReorderBuffer`).

The bookkeeping (:class:`PoolState`) needs no Zenoh; :class:`WorkerPool` wires it to a session.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import math
import os
import re
import socket
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, TypedDict

import msgpack

from vpp_service.frame import StereoFrame

if TYPE_CHECKING:
    import zenoh

log = logging.getLogger(__name__)

#: Characters a worker id may hold: one Zenoh key chunk, no wildcards or separators.
_WORKER_ID = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")


def check_worker_id(worker_id: str) -> str:
    """Return ``worker_id`` when it is a valid id (1-64 of ``A-Z a-z 0-9 _ . -``).

    Raises
    ------
    ValueError
        It is not; the message names the rule.
    """
    if not isinstance(worker_id, str) or not _WORKER_ID.match(worker_id):
        raise ValueError(f"worker_id must be 1-64 characters of A-Z a-z 0-9 _ . -, got {worker_id!r}")
    return worker_id


def default_worker_id() -> str:
    """``<host>-<pid>``: unique on a network of hosts with distinct names."""
    host = re.sub(r"[^A-Za-z0-9_.\-]", "-", socket.gethostname())[:48] or "host"
    return f"{host}-{os.getpid()}"


def weight(seq: int, member: str) -> int:
    """Rendezvous weight of ``member`` for frame ``seq``: 64 bits of blake2b, the same in every process."""
    h = hashlib.blake2b(seq.to_bytes(8, "big", signed=False) + member.encode(), digest_size=8)
    return int.from_bytes(h.digest(), "big")


def rendezvous_order(seq: int, members: Iterable[str]) -> list[str]:
    """``members`` by decreasing :func:`weight` for ``seq`` (ties by id): the owner first, then its successors."""
    return sorted(members, key=lambda m: (-weight(seq, m), m))


def owner(seq: int, members: Iterable[str]) -> str | None:
    """The member that owns frame ``seq`` (None without members)."""
    best: tuple[int, str] | None = None
    for m in members:
        key = (-weight(seq, m), m)
        if best is None or key < best:
            best = key
    return None if best is None else best[1]


# ----------------------------------------------------------------- answers
def encode_answered(rig: str, seq: int | None, worker: str) -> bytes:
    """The ``@answered`` message: ``{v: 1, rig, seq, worker}`` in msgpack; ``seq`` None: a heartbeat.

    A heartbeat (``{v: 1, rig, worker, alive: true}``) says the worker runs, with nothing new answered.
    """
    if seq is None:
        return msgpack.packb({"v": 1, "rig": rig, "worker": worker, "alive": True}, use_bin_type=True)
    return msgpack.packb({"v": 1, "rig": rig, "seq": int(seq), "worker": worker}, use_bin_type=True)


def decode_answered(payload: bytes) -> tuple[str, int | None, str]:
    """``(rig, seq, worker)`` of an ``@answered`` message; ``seq`` None for a heartbeat.

    Raises
    ------
    ValueError
        Not such a message (names the field).
    """
    if len(payload) > 512:
        raise ValueError(f"@answered: {len(payload)} bytes, at most 512")
    try:
        msg = msgpack.unpackb(payload, raw=False)
    except Exception as exc:  # noqa: BLE001 - msgpack raises several types on junk
        raise ValueError(f"@answered: not msgpack: {exc}") from None
    if not isinstance(msg, dict) or msg.get("v") != 1:
        raise ValueError("@answered: must be a map with v = 1")
    rig, seq, worker = msg.get("rig"), msg.get("seq"), msg.get("worker")
    if not isinstance(rig, str):
        raise ValueError("@answered.rig: must be a string")
    if seq is None and msg.get("alive") is True:
        pass  # a heartbeat
    elif isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < 1 << 63:
        raise ValueError("@answered.seq: must be an int in [0, 2^63)")
    if not isinstance(worker, str) or not _WORKER_ID.match(worker):
        raise ValueError("@answered.worker: must be a worker id")
    return rig, seq, worker


# ------------------------------------------------------------- bookkeeping
class PoolStatus(TypedDict):
    """What a worker reports about the pool (``@status["pool"]``)."""

    worker: str
    members: list[str]
    share: float
    deadline_ms: float
    seen: int
    own: int
    taken_over: int
    lost: int
    duplicates: int
    held: int
    handed_over: int
    joins: int
    leaves: int
    bad_answers: int
    foreign_answers: int
    silent: list[str]
    silenced: int
    silent_lost: int


@dataclass
class _Record:
    """A frame this worker saw but did not own: whose it is, when it came, the frame while it is fresh."""

    owner: str
    t: float
    frame: StereoFrame | None


class PoolState:
    """Membership, ownership and failover bookkeeping of one worker (thread-safe, no Zenoh).

    Parameters
    ----------
    me : str
        This worker's id (always a member).
    deadline_s : float
        A frame older than this is not taken over from a dead member (counted ``lost``).
    hold_frames : int
        At most this many frames of other members kept for a takeover (the oldest first lose their image).
    record_frames : int
        At most this many records (seq, owner, arrival) of other members' unanswered frames; a record
        is also forgotten after ``max(10 s, 10 * deadline_s)`` (its owner dropped it, counted there,
        or is that far behind).
    answers_kept : int
        How many recent answered ``seq`` values are remembered (duplicate detection).
    silent_frames : int
        A member is silent once it owns this many unanswered frames older than ``silent_s``
        and has said nothing (answer or heartbeat) for ``silent_s``.
    silent_s : float or None
        See ``silent_frames``; None: the deadline, at least 1 s (one found silent wrongly costs
        duplicates).
    clock : callable
        Monotonic seconds (tests pass their own).
    """

    def __init__(
        self,
        me: str,
        *,
        deadline_s: float = 1.0,
        hold_frames: int = 64,
        record_frames: int = 4096,
        answers_kept: int = 4096,
        silent_frames: int = 1,
        silent_s: float | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.me = check_worker_id(me)
        self.deadline_s = deadline_s
        self.hold_frames = hold_frames
        self.record_frames = record_frames
        self.answers_kept = answers_kept
        self.silent_frames = silent_frames
        self.silent_s = max(deadline_s, 1.0) if silent_s is None else silent_s
        self.clock = clock
        self._lock = threading.Lock()
        self._members: set[str] = {me}
        self._silent: set[str] = set()  # members that own no frame until they answer again
        self._last_heard: dict[str, float] = {}  # member -> when its latest answer or heartbeat came
        self._silent_lost: OrderedDict[int, None] = OrderedDict()  # counted silent_lost, until answered
        self._records: OrderedDict[int, _Record] = OrderedDict()  # by arrival
        self._held: deque[int] = deque()  # seqs whose record still holds the frame, by arrival
        self._answers: OrderedDict[int, set[str]] = OrderedDict()
        self._mine: OrderedDict[int, None] = OrderedDict()  # seqs this worker took (own and taken over)
        self._dup_counted: set[int] = set()
        self._leaving = False
        self._counts = {
            "seen": 0,
            "own": 0,
            "taken_over": 0,
            "lost": 0,
            "duplicates": 0,
            "handed_over": 0,
            "joins": 0,
            "leaves": 0,
            "bad_answers": 0,
            "foreign_answers": 0,
            "silenced": 0,
            "silent_lost": 0,
        }

    @property
    def members(self) -> list[str]:
        """The live members (sorted)."""
        with self._lock:
            return sorted(self._members)

    def _owners(self) -> set[str]:
        """The members that own frames: all but the silent ones (lock held)."""
        return self._members - self._silent

    def admit(self, frame: StereoFrame) -> bool:
        """Whether this worker processes ``frame``; otherwise it is recorded (and held while fresh).

        A frame this worker owns is processed whatever others announced for it (see Trust above).
        """
        now = self.clock()
        with self._lock:
            if self._leaving:
                return False  # the others own every frame now
            self._counts["seen"] += 1
            seq = frame.seq
            if seq in self._mine or seq in self._records:
                return False  # a repeat of a frame seen before
            who = owner(seq, self._owners())
            if who == self.me:
                self._counts["own"] += 1
                self._take(seq)
                return True
            assert who is not None
            if who in self._answers.get(seq, ()):
                return False  # its owner answered it already
            self._records[seq] = _Record(who, now, frame)
            self._held.append(seq)
            self._trim(now)
            return False

    def _trim(self, now: float) -> None:
        """Drop images past the deadline or beyond ``hold_frames``, records beyond ``record_frames`` (lock held)."""
        while self._held:
            rec = self._records.get(self._held[0])
            if rec is None or rec.frame is None:
                self._held.popleft()
            elif now - rec.t > self.deadline_s or len(self._held) > self.hold_frames:
                rec.frame = None
                self._held.popleft()
            else:
                break
        horizon = max(10.0, 10 * self.deadline_s)
        while self._records and (
            len(self._records) > self.record_frames or now - next(iter(self._records.values())).t > horizon
        ):
            self._records.popitem(last=False)

    def answered(self, seq: int, worker: str) -> None:
        """``worker`` answered ``seq`` (this worker's own answers too): count duplicates.

        The record of another member's frame is forgotten only when its owner answers it.
        """
        with self._lock:
            rec = self._records.get(seq)
            if rec is not None and rec.owner == worker:
                del self._records[seq]
            if self._silent_lost.pop(seq, False) is None:  # a silent member answered it after all
                self._counts["silent_lost"] -= 1
            who = self._answers.get(seq)
            if who is None:
                who = self._answers[seq] = set()
                while len(self._answers) > self.answers_kept:
                    old, _ = self._answers.popitem(last=False)
                    self._dup_counted.discard(old)
            who.add(worker)
            # each answer past the first is counted once, by an answering worker other than the smallest id
            if self.me in who and self.me != min(who) and seq not in self._dup_counted:
                self._dup_counted.add(seq)
                self._counts["duplicates"] += 1

    def member_answered(self, seq: int, worker: str) -> bool:
        """:meth:`answered` when ``worker`` is a live member; otherwise counted (``foreign_answers``) and ignored.

        Anyone on the network can put an ``@answered`` message: one from a worker id that holds no
        ``@pool`` token must not make the owner skip its frame (a forged answer would silence it).
        """
        if not self.heard(worker):
            with self._lock:
                self._counts["foreign_answers"] += 1
            return False
        self.answered(seq, worker)
        return True

    def heard(self, worker: str) -> bool:
        """``worker`` spoke (an answer or a heartbeat): a silent member owns frames again.

        Returns False, and changes nothing, when ``worker`` holds no token (a heartbeat can come
        before the token of a worker that just joined: it is not counted).
        """
        with self._lock:
            if worker not in self._members:
                return False
            self._last_heard[worker] = self.clock()
            if worker in self._silent:
                self._silent.discard(worker)
                log.info("pool: %s speaks again; it owns frames again", worker)
        return True

    def check_silent(self) -> list[StereoFrame]:
        """Find silent members (see Trust above); returns the fresh frames this worker takes over from them.

        A member becomes silent when it owns at least ``silent_frames`` unanswered frames older
        than ``silent_s`` and has said nothing (answer or heartbeat) for ``silent_s``. Its frames
        go to their next owner as when it leaves; those that fall to this worker are taken over
        while fresh, the older ones counted ``silent_lost``.
        """
        now = self.clock()
        with self._lock:
            if self._leaving:
                return []  # the others own every frame now
            overdue: dict[str, list[float]] = {}
            for rec in self._records.values():  # by arrival: the overdue ones come first
                if now - rec.t <= self.silent_s:
                    break
                if rec.owner in self._members and rec.owner not in self._silent:
                    overdue.setdefault(rec.owner, []).append(rec.t)
            found = [
                m
                for m, times in overdue.items()
                if len(times) >= self.silent_frames and self._last_heard.get(m, -math.inf) < now - self.silent_s
            ]
            if not found:
                return []
            for m in found:
                self._silent.add(m)
                self._counts["silenced"] += 1
                log.warning(
                    "pool: member %s owns %d frames past the deadline and has said nothing since: "
                    "its frames go to the others until it speaks",
                    m,
                    len(overdue[m]),
                )
            return self._reassign(set(found), now, "silent_lost")

    def _take(self, seq: int) -> None:
        """Remember that this worker processes ``seq`` (lock held)."""
        self._mine[seq] = None
        while len(self._mine) > self.answers_kept:
            self._mine.popitem(last=False)

    def expects(self, seq: int) -> bool:
        """Whether ``seq`` is this worker's to answer (own or taken over): a hole in its outputs is a gap."""
        with self._lock:
            return seq in self._mine

    def leave(self) -> None:
        """Stop taking frames: this worker is leaving the pool."""
        with self._lock:
            self._leaving = True

    def handed_over(self, n: int) -> None:
        """Count ``n`` queued frames a leaving worker left to its successors."""
        with self._lock:
            self._counts["handed_over"] += n

    def bad_answer(self) -> None:
        """Count an ``@answered`` message that could not be read."""
        with self._lock:
            self._counts["bad_answers"] += 1

    def joined(self, worker: str) -> None:
        """``worker``'s token appeared."""
        with self._lock:
            if worker not in self._members:
                self._members.add(worker)
                self._counts["joins"] += 1

    def left(self, worker: str) -> list[StereoFrame]:
        """``worker``'s token disappeared: returns the frames this worker takes over (fresh ones, by seq).

        The departed member's unanswered frames whose successor is this worker
        and that are older than the deadline (or no longer held) are counted as lost.
        """
        if worker == self.me:
            return []  # our own token is ours until we stop
        now = self.clock()
        with self._lock:
            if worker not in self._members:
                return []
            self._members.discard(worker)
            self._silent.discard(worker)
            self._last_heard.pop(worker, None)
            self._counts["leaves"] += 1
            return self._reassign({worker}, now, "lost")

    def _reassign(self, gone: set[str], now: float, lost: str) -> list[StereoFrame]:
        """Give the records of ``gone`` to their next owners; returns this worker's fresh ones (lock held).

        Older ones that fall to this worker (or whose image it no longer holds) are counted in ``lost``.
        """
        owners = self._owners()
        take: list[StereoFrame] = []
        for seq, rec in list(self._records.items()):
            if rec.owner not in gone:
                continue
            succ = owner(seq, owners)
            assert succ is not None
            if succ != self.me:
                rec.owner = succ  # another member's now; if it fails too, its successor decides
                continue
            del self._records[seq]
            if rec.frame is not None and now - rec.t <= self.deadline_s:
                take.append(rec.frame)
                self._take(seq)
                self._counts["taken_over"] += 1
            else:
                self._counts[lost] += 1
                if lost == "silent_lost":
                    self._silent_lost[seq] = None
                    while len(self._silent_lost) > self.answers_kept:
                        self._silent_lost.popitem(last=False)
        take.sort(key=lambda f: f.seq)
        return take

    def status(self) -> PoolStatus:
        """Counters, the members and this worker's nominal share."""
        with self._lock:
            self._trim(self.clock())
            members = sorted(self._members)
            silent = sorted(self._silent)
            owners = len(self._owners() | {self.me})
            c = dict(self._counts)
            held = len(self._held)
        return {
            "worker": self.me,
            "members": members,
            "share": 1.0 / owners,
            "deadline_ms": self.deadline_s * 1e3,
            "seen": c["seen"],
            "own": c["own"],
            "taken_over": c["taken_over"],
            "lost": c["lost"],
            "duplicates": c["duplicates"],
            "held": held,
            "handed_over": c["handed_over"],
            "joins": c["joins"],
            "leaves": c["leaves"],
            "bad_answers": c["bad_answers"],
            "foreign_answers": c["foreign_answers"],
            "silent": silent,
            "silenced": c["silenced"],
            "silent_lost": c["silent_lost"],
        }


# -------------------------------------------------------------- on Zenoh
def pool_key(prefix: str, rig: str, worker: str = "*") -> str:
    """The liveliness key of ``worker`` in the rig's pool (``*``: every member)."""
    from vpp_service.transport.wire import topic

    return topic(prefix, rig, f"@pool/{worker}")


def answered_key(prefix: str, rig: str) -> str:
    """The key the pool's answers go on."""
    from vpp_service.transport.wire import topic

    return topic(prefix, rig, "@answered")


#: Where a taken-over frame goes (the pipeline's input); returns whether it was queued.
Inject = Callable[[StereoFrame], bool]


class WorkerPool:
    """One worker's membership in its rig's pool, on a Zenoh session (see the module docstring).

    Parameters
    ----------
    session : zenoh.Session
        The service's session.
    prefix, rig : str
        The rig served.
    worker_id : str
        This worker's id (unique in the pool).
    deadline_ms : float
        ``pool_deadline_ms``: how fresh a dead member's frame must be to be taken over.
    join_wait_s : float
        How long :meth:`start` waits for the liveliness query listing the members.
    """

    def __init__(
        self,
        session: zenoh.Session,
        prefix: str,
        rig: str,
        worker_id: str,
        *,
        deadline_ms: float = 1000.0,
        join_wait_s: float = 1.0,
    ) -> None:
        self.session = session
        self.prefix, self.rig = prefix, rig
        self.worker_id = check_worker_id(worker_id)
        self.state = PoolState(worker_id, deadline_s=deadline_ms / 1e3)
        self.join_wait_s = join_wait_s
        self._inject: Inject | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._members_sub: zenoh.Subscriber[None] | None = None
        self._answers_sub: zenoh.Subscriber[None] | None = None
        self._publisher: zenoh.Publisher | None = None
        self._takeovers: deque[StereoFrame] = deque()
        self._wake = threading.Condition()
        self._stopping = False
        self._thread: threading.Thread | None = None
        self.last_leave: float | None = None  # monotonic time of the latest token loss
        #: The pipeline announces each frame once every sink has written it; False when a sink does (zenoh)
        self.answer_on_publish = True

    def start(self, inject: Inject) -> None:
        """Declare the token, learn the members, watch answers; taken-over frames go to ``inject``."""
        import zenoh

        self._inject = inject
        live = self.session.liveliness()
        prefix = pool_key(self.prefix, self.rig, "")
        self._members_sub = live.declare_subscriber(
            pool_key(self.prefix, self.rig), zenoh.handlers.Callback(self._on_member), history=True
        )
        self._token = live.declare_token(pool_key(self.prefix, self.rig, self.worker_id))
        for reply in live.get(pool_key(self.prefix, self.rig), timeout=self.join_wait_s):
            if reply.ok is not None:
                self.state.joined(str(reply.ok.key_expr)[len(prefix) :])
        key = answered_key(self.prefix, self.rig)
        self._answers_sub = self.session.declare_subscriber(key, zenoh.handlers.Callback(self._on_answer))
        self._publisher = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        self._heartbeat()
        self._thread = threading.Thread(target=self._run, name="pool-takeover", daemon=True)
        self._thread.start()
        log.info("pool %s: worker %s joined; members %s", self.rig, self.worker_id, self.state.members)

    def admit(self, frame: StereoFrame) -> bool:
        """Whether this worker processes ``frame`` (it is tagged with this worker's id when so)."""
        if self.state.admit(frame):
            frame.meta["worker"] = self.worker_id
            return True
        return False

    def answered(self, seq: int) -> None:
        """Record that this worker answered ``seq`` (its outputs are out) and tell the pool."""
        self.state.answered(seq, self.worker_id)
        pub = self._publisher
        if pub is not None:
            try:
                pub.put(encode_answered(self.rig, seq, self.worker_id))
            except Exception as exc:  # noqa: BLE001 - a closing session; the answer is only bookkeeping
                log.debug("pool: announcing seq %d failed: %s", seq, exc)

    def _heartbeat(self) -> None:
        """Tell the pool this worker runs (see Trust above)."""
        pub = self._publisher
        if pub is not None and not self._stopping:
            try:
                pub.put(encode_answered(self.rig, None, self.worker_id))
            except Exception as exc:  # noqa: BLE001 - a closing session; the heartbeat is only bookkeeping
                log.debug("pool: heartbeat failed: %s", exc)

    def _on_member(self, sample: zenoh.Sample) -> None:
        import zenoh

        worker = str(sample.key_expr).rsplit("/", 1)[-1]
        if sample.kind == zenoh.SampleKind.PUT:
            self.state.joined(worker)
            log.info("pool %s: %s joined", self.rig, worker)
            return
        frames = self.state.left(worker)
        self.last_leave = time.monotonic()
        if worker == self.worker_id:  # its own token, undeclared as it stops: a clean exit, not news
            log.debug("pool %s: %s (this worker) left", self.rig, worker)
        elif frames:
            log.warning("pool %s: %s left; taking over %d frame(s)", self.rig, worker, len(frames))
        else:
            log.info("pool %s: %s left", self.rig, worker)
        if frames:
            with self._wake:
                self._takeovers.extend(frames)
                self._wake.notify()

    def _on_answer(self, sample: zenoh.Sample) -> None:
        try:
            rig, seq, worker = decode_answered(sample.payload.to_bytes())
        except ValueError:
            self.state.bad_answer()
            return
        if rig != self.rig or worker == self.worker_id:
            return
        if seq is None:
            self.state.heard(worker)
        else:
            self.state.member_answered(seq, worker)  # the word of a non-member skips no frame

    def _run(self) -> None:
        """Hand taken-over frames to the pipeline (off Zenoh's thread: the input may block).

        Between frames, every quarter of ``silent_s``, it puts this worker's heartbeat and looks
        for silent members.
        """
        period = self.state.silent_s / 4
        next_check = time.monotonic() + period
        while True:
            with self._wake:
                while not self._takeovers and not self._stopping:
                    wait = next_check - time.monotonic()
                    if wait <= 0:
                        break
                    self._wake.wait(wait)
                if self._stopping:
                    return
                if not self._takeovers:
                    next_check = time.monotonic() + period
                    self._heartbeat()
                    self._takeovers.extend(self.state.check_silent())
                    continue
                frame = self._takeovers.popleft()
            frame.meta["worker"] = self.worker_id
            if self._inject is not None:
                self._inject(frame)

    def status(self) -> PoolStatus:
        """See :meth:`PoolState.status`."""
        return self.state.status()

    def leave(self) -> None:
        """Leave the pool (a clean stop): take no frame any more and withdraw the token.

        The others see the token go and take over this worker's unanswered
        frames; answers of the frames it still finishes keep going out until :meth:`stop`.
        """
        self.state.leave()
        token, self._token = self._token, None
        if token is not None:
            with contextlib.suppress(Exception):  # the session may be closed already
                token.undeclare()

    def stop(self) -> None:
        """Leave the pool: undeclare everything, stop the takeover thread."""
        with self._wake:
            self._stopping = True
            self._wake.notify_all()
        if self._thread is not None:
            self._thread.join(2.0)
        self.state.leave()
        for obj in (self._token, self._members_sub, self._answers_sub, self._publisher):
            if obj is not None:
                with contextlib.suppress(Exception):  # the session may be closed already
                    obj.undeclare()
        self._token = self._members_sub = self._answers_sub = self._publisher = None


__all__ = [
    "Inject",
    "PoolState",
    "PoolStatus",
    "WorkerPool",
    "answered_key",
    "check_worker_id",
    "decode_answered",
    "default_worker_id",
    "encode_answered",
    "owner",
    "pool_key",
    "rendezvous_order",
    "weight",
]

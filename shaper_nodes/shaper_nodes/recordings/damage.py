"""What a damaged or unclosed recording lost (:class:`Damage`, filled in by :mod:`.recovery`'s scan), and how it is
said.

A recording that was not closed is described plainly (:func:`describe_unclosed`): how many
messages were read, where the data ends, and, from the last heartbeat the suite's recorder wrote
into it (:mod:`.heartbeat`), until when the recorder was alive and how much it lost at most after
its last flush (seconds and messages per topic). :func:`describe_damage` says the rest: the bytes
and the log times lost, the corrupt chunks skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .heartbeat import Heartbeat, LossBound


@dataclass
class Damage:
    """What a damaged MCAP file lost.

    Attributes
    ----------
    path : str
        The file.
    size : int
        File size, bytes.
    readable : int
        Bytes up to the end of the last complete record, from the start of the file.
    reason : str
        Why reading stopped (or "" if it reached the end).
    lost_time : tuple of (int, int) or None
        Log-time range (ns) of the messages in the chunk that was cut, from its header.
    skipped_chunks : list of str
        Chunks skipped because their data was corrupt (and why).
    expected_messages : int or None
        Message count that metadata.yaml promises, if it exists.
    messages_read : int
        Messages read from the file (the recorder's heartbeats not counted).
    data_start, data_end : int or None
        Log times of the first and last message read, ns (heartbeats not counted).
    heartbeat : Heartbeat or None
        The last recorder heartbeat read (None: the file has none).
    loss : LossBound or None
        What was lost after the last flush, at most (from the heartbeat).
    """

    path: str
    size: int
    readable: int
    reason: str = ""
    lost_time: tuple[int, int] | None = None
    skipped_chunks: list[str] = field(default_factory=list)
    expected_messages: int | None = None
    messages_read: int = 0
    data_start: int | None = None
    data_end: int | None = None
    heartbeat: Heartbeat | None = None
    loss: LossBound | None = None

    @property
    def not_closed(self) -> bool:
        """The file ends without its footer (the writer stopped before closing it)."""
        return self.reason == "the file ends without a footer" or self.reason.startswith("cut inside")

    @property
    def lost_bytes(self) -> int:
        return self.size - self.readable

def _sec(ns: int) -> float:
    return ns * 1e-9


def _when(ns: int, origin: int | None) -> str:
    """A log time as seconds from ``origin``, with the UTC clock time when it looks like wall time."""
    text = f"{_sec(ns - (origin or 0)):.3f} s"
    if ns > 10**18:  # after 2001: a wall clock, not simulated time
        import datetime

        clock = datetime.datetime.fromtimestamp(ns * 1e-9, tz=datetime.UTC).strftime("%Y-%m-%d %H:%M:%S.%f")
        text += f" ({clock[:-3]} UTC)"
    return text

def describe_unclosed(d: Damage) -> str:
    """What a recording that was not closed holds and lost, in one sentence (see the module docstring)."""
    if d.data_end is None:
        head = f"recording not closed (recorder killed?): no message in {d.path}"
    else:
        head = (f"recording not closed (recorder killed?): {d.messages_read} messages read, data ends at"
                f" {_when(d.data_end, d.data_start)} from its first message")
    if d.loss is None or d.heartbeat is None:
        return head + ("; the file has no recorder heartbeat, so how much the recorder still held when it stopped"
                       " is not known")
    loss, beat = d.loss, d.heartbeat
    origin = d.data_start if d.data_start is not None else beat.stamp_ns
    per_topic = ", ".join(f"{t} {n}" for t, n in sorted(loss.messages.items()))
    text = f"{head}; the recorder had written everything it received until {_when(beat.stamp_ns, origin)}"
    if loss.alive_ns > beat.stamp_ns:
        text += f" and was still alive at {_sec(loss.alive_ns - origin):.3f} s (the chunk it was writing was cut)"
    text += (f"; lost after its last flush: at most ~{loss.seconds:.1f} s, {loss.total} messages ({per_topic};"
             f" at the rates it measured, if its writer kept the pace of its {beat.flush_period:g} s flushes)")
    if loss.dropped:
        text += (f"; it had also dropped {sum(loss.dropped.values())} message(s) (queue full: "
                 + ", ".join(f"{t} {n}" for t, n in sorted(loss.dropped.items())) + ")")
    return text

def describe_damage(d: Damage) -> str:
    """One sentence on what a damaged file lost."""
    if not d.reason and not d.skipped_chunks:
        return f"{d.path}: read to the end"
    parts = []
    if d.not_closed:
        parts.append(describe_unclosed(d))
    if d.reason and d.reason != "the file ends without a footer":
        parts.append(f"{d.path}: {d.reason}; read {d.readable} of {d.size} bytes, {d.lost_bytes} bytes"
                     f" ({100.0 * d.lost_bytes / max(d.size, 1):.1f} %) lost")
        if d.lost_time is not None:
            a, b = d.lost_time
            parts.append(f"the cut chunk held messages logged {_sec(a):.3f}-{_sec(b):.3f} s")
    if d.skipped_chunks:
        parts.append(f"{len(d.skipped_chunks)} corrupt chunk(s) skipped: " + "; ".join(d.skipped_chunks))
    return "; ".join(parts)

"""Where the samples of a live session come from (``aacmm live SOURCE``, docs/live.md):

* a file: a recorded stream, replayed at its own time stamps (``--speed``, see :class:`Pacer`);
* ``-``: standard input (a vendor SDK's adapter printing CSV lines, ``adapter | aacmm live - ...``);
* ``tcp://HOST:PORT``: the session connects to a server that sends the lines (the header first);
* ``udp://HOST:PORT``: the session listens on that address; each datagram holds one or more whole
  lines. The header may be sent again (a repeated header line is skipped), so that a session started
  late can join; data before the first header are counted and skipped.

Every source yields ``(line number, bytes of the line without its end)`` and, while nothing comes, an
idle ``None`` at least every :data:`TICK_S` seconds (so that the session flushes its record and the
view stays alive). A stream ends at its end (end of file, the connection closed); a connection reset (or
broken otherwise) is an ``OSError`` naming the connection, never an end; a UDP source never ends by itself
(``--stop-after-idle-s``, Ctrl-C or SIGTERM end it).
"""
from __future__ import annotations

import os
import re
import selectors
import socket
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import InputError, decode_text, open_input

__all__ = ["open_source", "LineSource", "Pacer", "TICK_S", "AHEAD_S", "MAX_LINE_BYTES", "CHUNK_LINES", "LongLine",
           "line_text", "chunk_texts"]

#: the longest wait without a sign of life [s]
TICK_S = 0.25
#: a replayed sample is released at most this early [s]
AHEAD_S = 0.01
_CHUNK = 1 << 16
#: the receive buffer a UDP source asks the kernel for [bytes]: at 1 kHz a stall of seconds (a slow disk, a loaded
#: machine) loses no datagram. Linux grants at most ``net.core.rmem_max`` unless the process may force more.
UDP_BUFFER_BYTES = 8 << 20
#: the most lines of a file read at once (and at most about :data:`_CHUNK` bytes)
CHUNK_LINES = 1024
#: the longest line a stream may send [bytes] (a sample line is a few hundred): a longer one is a bad line, its
#: bytes dropped as they come (a peer that never sends a newline cannot fill the memory)
MAX_LINE_BYTES = 1 << 20


class LongLine(bytes):
    """What a source yields for a line longer than :data:`MAX_LINE_BYTES`: its first bytes, ``length`` the
    bytes it held (at least, when the stream ended inside it)."""
    length = 0


def _long(head: bytes, length: int) -> LongLine:
    out = LongLine(head[:40])
    out.length = length
    return out


def chunk_texts(chunk: list, name: str) -> list:
    """The texts of the lines of a chunk (:meth:`LineSource.chunks`): ``(line number, text)`` for each, or the
    :class:`InputError` :func:`line_text` gives for one; the chunk's bytes decoded at once when they are plain."""
    if not any(isinstance(raw, LongLine) for _, raw in chunk):
        data = b"\n".join(raw for _, raw in chunk)
        if b"\0" not in data and b"\r" not in data:
            try:
                text = data.decode("utf-8")
            except UnicodeDecodeError:
                pass
            else:
                return list(zip((no for no, _ in chunk), text.split("\n"), strict=True))
    out = []
    for no, raw in chunk:
        try:
            out.append((no, line_text(raw, name, no)))
        except InputError as exc:
            out.append(exc)
    return out


def line_text(raw: bytes, name: str, no: int) -> str:
    """The text of a line a source yielded: an InputError naming the stream and the line for one too long or
    not UTF-8."""
    if isinstance(raw, LongLine):
        decode_text(bytes(raw).rstrip(b"\r"), name, no)    # old Mac line ends (a CR alone) said as such
        raise InputError(f"a line of {raw.length} bytes or more, beyond the {MAX_LINE_BYTES} a line may hold (a "
                         f"sample line holds a few hundred; no line end?), starting {bytes(raw)!r}", name, no)
    # the rule of every file reader: UTF-8, no NUL byte, no carriage return alone (old Mac line ends)
    return decode_text(raw, name, no)


class LineSource:
    """Lines of one stream (see the module doc). ``name``: the stream for messages; ``replay``: True
    for a file (paced at its time stamps); ``datagrams``: True for UDP (headers may repeat).

    :meth:`lines` yields the lines one by one, :meth:`chunks` the lines that came together (a read of a pipe
    or a socket, a datagram, a stretch of a file) as lists: both continue where the other stopped."""
    name = "<stream>"
    replay = False
    datagrams = False
    _it = None
    _rest: list | None = None

    def _chunk_iter(self):
        if self._it is None:
            self._it = self._chunks()
        return self._it

    def lines(self):
        """Every line, one by one (and the idle ``None`` ticks)."""
        it = self._chunk_iter()
        while True:
            if self._rest:
                yield self._rest.pop(0)
                continue
            chunk = next(it, False)
            if chunk is False:
                return
            if chunk is None:
                yield None
            else:
                self._rest = list(chunk)

    def chunks(self):
        """Lists of ``(line number, bytes)`` that came together (never empty), and the idle ``None`` ticks."""
        it = self._chunk_iter()
        if self._rest:
            rest, self._rest = self._rest, None
            yield rest
        for chunk in it:        # not ``yield from``: a generator dropped would close the stream's own  # noqa: UP028
            yield chunk

    def _chunks(self):
        raise NotImplementedError

    def close(self) -> None:
        pass


class _FileSource(LineSource):
    replay = True

    def __init__(self, path: Path):
        self.name = str(path)
        self._fh = open_input(path, "the sample stream")

    def _chunks(self):
        no, chunk, size = 0, [], 0
        while raw := self._fh.readline(MAX_LINE_BYTES + 1):
            no += 1
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                head, length = raw, len(raw)
                while raw and not raw.endswith(b"\n"):     # the rest of it, a bounded piece at a time
                    raw = self._fh.readline(MAX_LINE_BYTES)
                    length += len(raw)
                chunk.append((no, _long(head, length)))
            else:
                chunk.append((no, raw.rstrip(b"\r\n") if raw.endswith(b"\n") else raw))
            size += len(raw)
            if len(chunk) >= CHUNK_LINES or size >= _CHUNK:
                yield chunk
                chunk, size = [], 0
        if chunk:
            yield chunk

    def close(self) -> None:
        self._fh.close()


class _FdSource(LineSource):
    """Lines read from a file descriptor (standard input, a TCP socket) with idle ticks."""

    def __init__(self, fd: int, name: str, owner: socket.socket | None = None):
        self.fd, self.name, self._owner = fd, name, owner

    def _read(self) -> bytes:
        return os.read(self.fd, _CHUNK)

    def _chunks(self):
        sel: selectors.BaseSelector = selectors.DefaultSelector()
        try:
            sel.register(self.fd, selectors.EVENT_READ)
        except PermissionError:     # epoll refuses a regular file or /dev/null (`live - < samples.csv`): select()
            sel.close()             # takes them, always ready
            sel = selectors.SelectSelector()
            sel.register(self.fd, selectors.EVENT_READ)
        # rest: the line begun and not ended (only its first bytes once it is longer than MAX_LINE_BYTES, so a peer
        # that never sends a newline cannot fill the memory), length: its bytes so far
        rest, length, too_long, no = bytearray(), 0, False, 0
        try:
            while True:
                if not sel.select(TICK_S):
                    yield None
                    continue
                data = self._read()
                if not data:
                    break
                *ended, last = data.split(b"\n")
                chunk = []
                for part in ended:
                    no += 1
                    total = length + len(part)
                    if too_long or total > MAX_LINE_BYTES:
                        chunk.append((no, _long(bytes(rest) or part, total)))
                    else:
                        chunk.append((no, (bytes(rest) + part).rstrip(b"\r")))
                    rest, length, too_long = bytearray(), 0, False
                length += len(last)
                if not too_long and length > MAX_LINE_BYTES:
                    too_long, rest = True, (rest + last)[:40]
                elif not too_long:
                    rest += last
                    if b"\r" in last.rstrip(b"\r"):     # old Mac line ends: said now, not after 1 MiB
                        no += 1
                        chunk.append((no, bytes(rest)))
                        rest, length = bytearray(), 0
                if chunk:
                    yield chunk
            if too_long:
                yield [(no + 1, _long(bytes(rest), length))]
            elif rest:
                yield [(no + 1, bytes(rest).rstrip(b"\r"))]
        finally:
            sel.close()

    def close(self) -> None:
        if self._owner is not None:
            self._owner.close()


class _TcpSource(_FdSource):
    def __init__(self, host: str, port: int, spec: str):
        try:
            sock = socket.create_connection((host, port), timeout=10)
        except OSError as exc:
            raise InputError(f"cannot connect to {spec}: {exc.strerror or exc}") from None
        sock.settimeout(None)
        super().__init__(sock.fileno(), spec, sock)
        self._sock = sock

    def _read(self) -> bytes:
        try:
            return self._sock.recv(_CHUNK)
        except ConnectionError as exc:  # a reset is no end of the stream: what the server had still to send is lost
            raise OSError(exc.errno, f"the server broke the connection ({exc.strerror or exc})", self.name) from None


class _UdpSource(LineSource):
    datagrams = True

    def __init__(self, host: str, port: int, spec: str):
        self.name = spec
        self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except OSError as exc:
            self._sock.close()
            raise InputError(f"cannot listen on {spec}: {exc.strerror or exc}") from None
        self._sock.settimeout(TICK_S)
        self.buffer_bytes = self._ask_buffer(UDP_BUFFER_BYTES)

    def _ask_buffer(self, size: int) -> int:
        """Asks for a receive buffer of ``size`` bytes (forced where the process may, else as much as the
        system allows) and returns what the kernel granted."""
        for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
            if option is None:
                continue
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, option, size)
                break
            except OSError:
                continue
        return int(self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF))

    @property
    def address(self) -> tuple:
        """The (host, port) bound (port 0 in the spec takes a free one)."""
        return self._sock.getsockname()[:2]

    def _chunks(self):
        no = 0
        while True:
            try:
                data = self._sock.recv(65536)
            except TimeoutError:
                yield None
                continue
            chunk = []
            for raw in data.split(b"\n"):
                raw = raw.rstrip(b"\r")
                if raw:
                    no += 1
                    chunk.append((no, raw))
            if chunk:
                yield chunk

    def close(self) -> None:
        self._sock.close()


_NET = re.compile(r"(tcp|udp)://(\[[^\]]+\]|[^:/\[\]]+):([0-9]{1,5})/?")


def open_source(spec: str) -> LineSource:
    """The source named on the command line (see the module doc); an InputError for what cannot be
    opened (a missing file, a refused connection, an address in use)."""
    if spec == "-":
        import sys
        return _FdSource(sys.stdin.fileno(), "<stdin>")
    m = _NET.fullmatch(spec)
    if m:
        kind, host, port = m.group(1), m.group(2).strip("[]"), int(m.group(3))
        if not 0 <= port <= 65535 or (kind == "tcp" and port == 0):
            raise InputError(f"{spec}: the port must be from {0 if kind == 'udp' else 1} to 65535")
        return (_TcpSource if kind == "tcp" else _UdpSource)(host, port, spec)
    if re.match(r"[a-z]+://", spec) or not spec.strip():
        raise InputError(f"{spec or repr(spec)}: not a source: give a file, '-' (standard input), tcp://HOST:PORT or "
                         "udp://HOST:PORT")
    return _FileSource(Path(spec))


class Pacer:
    """Replays time stamps at ``speed`` times real time (0: as fast as possible): :meth:`wait` returns
    when the sample of time ``t`` [s] is due (up to :data:`AHEAD_S` early: the samples of the next 10 ms
    go in one batch, not one sleep each), waiting in slices of at most :data:`TICK_S` and calling
    ``idle()`` between them (``idle`` returns True to stop waiting: an interruption)."""

    def __init__(self, speed: float):
        self.speed = float(speed)
        self._t0 = None
        self._w0 = 0.0

    def released(self, t: np.ndarray, k: int) -> int:
        """The end of the run of samples from ``k`` (times ``t`` (n,) [s]; sample ``k`` was waited for) that
        :meth:`wait` would release now without waiting (all of them at ``speed`` 0)."""
        if self.speed <= 0 or self._t0 is None:
            return len(t)
        due = self._w0 + (t[k + 1:] - self._t0) / self.speed
        ahead = np.flatnonzero(due - time.monotonic() > AHEAD_S)
        return k + 1 + int(ahead[0]) if len(ahead) else len(t)

    def wait(self, t: float, idle: Callable[[], bool] | None = None) -> bool:
        """True once due; False when ``idle()`` asked to stop."""
        if self.speed <= 0:
            return True
        if self._t0 is None:
            self._t0, self._w0 = t, time.monotonic()
            return True
        due = self._w0 + (t - self._t0) / self.speed
        while True:
            left = due - time.monotonic()
            if left <= AHEAD_S:
                return True
            time.sleep(min(left, TICK_S))
            if idle is not None and idle():
                return False

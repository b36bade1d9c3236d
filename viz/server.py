"""A headless meshcat server in a child process, with a connected :class:`meshcat.Visualizer`.

The server is meshcat's own ZMQ/websocket bridge (:mod:`viz.bridge`), listening on 127.0.0.1.
It stops when :meth:`MeshcatServer.close` is called, when the ``with`` block ends, at interpreter
exit (atexit), on SIGTERM/Ctrl-C of the parent, and by itself when the parent process is gone.
"""
from __future__ import annotations

import atexit
import contextlib
import io
import os
import selectors
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .errors import ViewerError

__all__ = ["MeshcatServer"]

_PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: the server process's program: viz/bridge.py run as ``__main__`` by its path, not as ``-m viz.bridge``, which would
#: import the viz package first (its ``__init__`` loads scipy and the arm model the bridge never uses: 0.5 s of CPU
#: at every start, measured); the argument after it, "viz.bridge", names the process and is dropped
_BRIDGE_PROGRAM = ("import runpy, sys; del sys.argv[1]; "
                   f"runpy.run_path({str(Path(__file__).with_name('bridge.py'))!r}, run_name='__main__')")


class MeshcatServer:
    """A meshcat server on ``host`` (127.0.0.1) with a visualizer connected to it.

    Args:
        port: web port; ``None`` takes the first free port from 7000 up. A busy port is an error.
        host: interface to listen on.
        timeout: seconds to wait for the server to start, and for each reply of the server.

    Use as a context manager, or call :meth:`start` and :meth:`close`::

        with MeshcatServer() as server:
            server.visualizer["box"].set_object(meshcat.geometry.Box([0.1, 0.1, 0.1]))
            print(server.url)
    """

    def __init__(self, port: int | None = None, host: str = "127.0.0.1", timeout: float = 30.0):
        if port is not None and not 0 < int(port) < 65536:
            raise ViewerError(f"--port must be between 1 and 65535, got {port}")
        self.port = None if port is None else int(port)
        self.host = host
        self._timeout = float(timeout)
        self.url: str | None = None
        self.zmq_url: str | None = None
        self._proc: subprocess.Popen | None = None
        self._vis = None

    @property
    def timeout(self) -> float:
        """Seconds to wait for the server to start and for each reply [s]; a new value applies at once to
        the connected visualizer's socket."""
        return self._timeout

    @timeout.setter
    def timeout(self, seconds: float) -> None:
        self._timeout = float(seconds)
        if self._vis is not None:
            self._set_socket_timeouts(self._vis.window.zmq_socket)

    def _set_socket_timeouts(self, sock) -> None:
        import zmq

        sock.setsockopt(zmq.RCVTIMEO, int(self._timeout * 1000))
        sock.setsockopt(zmq.SNDTIMEO, int(self._timeout * 1000))

    # -- lifecycle --------------------------------------------------------------------------
    def start(self) -> MeshcatServer:
        """Start the server process and connect a visualizer; raises :class:`ViewerError`."""
        if self._proc is not None:
            return self
        cmd = [sys.executable, "-u", "-c", _BRIDGE_PROGRAM, "viz.bridge", "--host", self.host,
               "--parent-pid", str(os.getpid())]
        if self.port is not None:
            cmd += ["--port", str(self.port)]
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_PROJECT_ROOT), env.get("PYTHONPATH")) if p)
        stderr = tempfile.TemporaryFile()
        self._proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=stderr, stdin=subprocess.DEVNULL, bufsize=0,
                                      env=env, cwd=str(_PROJECT_ROOT))
        atexit.register(self.close)
        try:
            lines = self._read_startup(stderr)
            if "error" in lines:
                kind, _, msg = lines["error"].partition(" ")
                if kind == "port-in-use":
                    raise ViewerError(f"port {self.port} on {self.host} is in use: choose another with --port "
                                      f"(or leave --port out to take the first free port from 7000)")
                raise ViewerError(f"the meshcat server could not listen on port {self.port}: {msg}")
            self.zmq_url, self.url = lines["zmq_url"], lines["web_url"]
            self.port = int(self.url.rstrip("/").rsplit(":", 1)[1].split("/")[0])
            self._vis = self._connect()
        except BaseException:
            self.close()
            raise
        finally:
            stderr.close()
        return self

    def _read_startup(self, stderr) -> dict:
        out: dict[str, str] = {}
        deadline = time.monotonic() + self.timeout
        sel = selectors.DefaultSelector()
        sel.register(self._proc.stdout, selectors.EVENT_READ)
        try:
            while "web_url" not in out and "error" not in out:
                left = deadline - time.monotonic()
                if left <= 0 or not sel.select(left):
                    raise ViewerError(f"the meshcat server did not start within {self.timeout:g} s")
                line = self._proc.stdout.readline().decode("utf-8", "replace").strip()
                if not line:
                    self._proc.wait(timeout=5)
                    stderr.seek(0)
                    tail = stderr.read().decode("utf-8", "replace").strip().splitlines()[-5:]
                    raise ViewerError(f"the meshcat server exited (code {self._proc.returncode}) before it was "
                                      "ready: " + (" | ".join(tail) or "no message"))
                key, _, value = line.partition("=")
                out[key] = value
        finally:
            sel.close()
        self._proc.stdout.close()
        return out

    def _connect(self):
        import meshcat
        import zmq

        with contextlib.redirect_stdout(io.StringIO()):   # meshcat prints its URL: the caller decides
            vis = meshcat.Visualizer(zmq_url=self.zmq_url)
        sock = vis.window.zmq_socket
        self._set_socket_timeouts(sock)
        sock.setsockopt(zmq.LINGER, 0)
        return vis

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    @property
    def visualizer(self):
        """The :class:`meshcat.Visualizer` connected to this server."""
        if self._vis is None:
            raise ViewerError("the meshcat server is not running (call start() or use `with`)")
        return self._vis

    def static_html(self) -> str:
        """The self-contained page of the current scene (meshcat's ``static_html``)."""
        import zmq

        try:
            return self.visualizer.static_html()
        except zmq.ZMQError as exc:
            raise ViewerError(f"the meshcat server at {self.url} did not answer ({exc}); it may have stopped") from None

    def close(self) -> None:
        """Stop the server process (idempotent)."""
        atexit.unregister(self.close)
        if self._vis is not None:
            with contextlib.suppress(Exception):
                self._vis.window.zmq_socket.close(linger=0)
            self._vis = None
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        if proc.stdout is not None and not proc.stdout.closed:
            proc.stdout.close()

    def __enter__(self) -> MeshcatServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"MeshcatServer(url={self.url!r}, running={self.running})"

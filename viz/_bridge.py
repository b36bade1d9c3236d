"""The meshcat server process (run by :class:`viz.server.MeshcatServer`, not by users).

meshcat's own ZMQ-to-websocket bridge, with three changes: the web server listens on the given
host only (meshcat's listens on every interface), a busy ``--port`` is reported on stdout as one
``error=`` line instead of a traceback, and the process stops by itself when its parent is gone
(so that a killed parent cannot leave a server behind). Protocol on stdout: ``zmq_url=...`` then
``web_url=...``, or ``error=<kind> <message>``.
"""
from __future__ import annotations

import argparse
import errno
import os
import signal
import sys


def _bridge_class():
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class Bridge(ZMQWebSocketBridge):
        def make_app(self):
            app = super().make_app()
            listen = app.listen
            app.listen = lambda port, **kw: listen(port, address=self.host, **kw)
            return app

    return Bridge


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=None, help="web port; default: the first free one from 7000")
    ap.add_argument("--parent-pid", type=int, default=None, help="stop when this process is gone")
    args = ap.parse_args(argv)

    import tornado.ioloop

    try:
        bridge = _bridge_class()(host=args.host, port=args.port)
    except OSError as exc:
        kind = "port-in-use" if exc.errno == errno.EADDRINUSE else "os-error"
        print(f"error={kind} {exc.strerror or exc}", flush=True)
        return 3
    print(f"zmq_url={bridge.zmq_url}", flush=True)
    print(f"web_url={bridge.web_url}", flush=True)
    sys.stdout = open(os.devnull, "w")   # nobody reads this pipe any more: never block on it

    loop = tornado.ioloop.IOLoop.current()
    signal.signal(signal.SIGTERM, lambda *_: loop.add_callback_from_signal(loop.stop))
    if args.parent_pid is not None:
        def watch_parent():
            if os.getppid() != args.parent_pid:
                loop.stop()
        tornado.ioloop.PeriodicCallback(watch_parent, 250).start()
    try:
        loop.start()
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())

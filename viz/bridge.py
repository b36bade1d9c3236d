"""The meshcat server process (run by :class:`viz.server.MeshcatServer`, not by users).

meshcat's own ZMQ-to-websocket bridge, with three changes: the web server listens on the given
host only (meshcat's listens on every interface), a busy ``--port`` is reported on stdout as one
``error=`` line instead of a traceback, and the process stops by itself when its parent is gone
(so that a killed parent cannot leave a server behind); it also serves the page of a live session at
``/live/`` (:data:`LIVE_PAGE`: meshcat's viewer with a text panel).

The scene reaches a page over its websocket, after the page has loaded: a headless browser that renders for a
virtual-time budget (``chromium --virtual-time-budget``, :mod:`viz.browser`) counts no time while a request is
pending, but a websocket message is no request, so a budget could run out before the scene arrived (a screenshot
of an empty scene when the server answered late, e.g. on a loaded machine). So the live page keeps one request
open, ``/live/hold``, until the server's mark that the whole scene has been sent (:data:`SCENE_SENT`, written
after the scene to every new websocket) has reached it; the server answers the request by itself after
:data:`HOLD_S` seconds (a page that never connects is not held for longer). Protocol on stdout: ``zmq_url=...`` then
``web_url=...``, or ``error=<kind> <message>``.
"""
from __future__ import annotations

import argparse
import errno
import os
import signal
import sys

#: the scene node whose object carries the text of the live page's panel (``userData.lines``)
PANEL_NODE = "aacmm/live/panel"
#: the command the server writes to a new websocket after the whole scene (meshcat's viewer ignores it)
SCENE_SENT = "aacmm_scene_sent"
#: how long the server keeps the live page's ``/live/hold`` request open at most [s]
HOLD_S = 30.0
#: the live page (``/live/``): meshcat's viewer plus a text panel. Commands that set the panel node's
#: object fill the panel instead of the scene; everything else is meshcat's own.
LIVE_PAGE = """<!DOCTYPE html>
<html><head><meta charset=utf-8><title>aacmm live</title>
<style>body{margin:0}#meshcat-pane{width:100vw;height:100vh;overflow:hidden}
#aacmm-panel{position:absolute;left:8px;top:8px;z-index:10;max-width:70%;margin:0;padding:6px 9px;
font:13px/1.35 monospace;color:#fff;background:rgba(0,0,0,0.6);border-radius:4px;white-space:pre-wrap}</style>
</head><body><div id="meshcat-pane"></div><pre id="aacmm-panel">waiting for the session ...</pre>
<script type="text/javascript" src="/static/main.min.js"></script>
<script>
var hold = new AbortController();   // a request open until the scene is here (see viz/bridge.py)
fetch("/live/hold", {signal: hold.signal, cache: "no-store"}).catch(function () {});
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
var meshcatCommand = viewer.handle_command.bind(viewer);
viewer.handle_command = function (cmd) {
  if (cmd.type === "SCENE_SENT") {
    hold.abort();
    return;
  }
  if (cmd.type === "set_object" && String(cmd.path).endsWith("/PANEL_NODE")) {
    var data = (cmd.object && cmd.object.object && cmd.object.object.userData) || {};
    document.getElementById("aacmm-panel").textContent = (data.lines || []).join("\\n");
    return;
  }
  meshcatCommand(cmd);
};
try { viewer.connect(); } catch (e) { console.info("not connected to the meshcat server: ", e); }
</script></body></html>
""".replace("PANEL_NODE", PANEL_NODE).replace("SCENE_SENT", SCENE_SENT)


def _bridge_class():
    import tornado.gen
    import tornado.iostream
    import tornado.web
    import umsgpack
    from meshcat.servers.zmqserver import ZMQWebSocketBridge

    class LivePage(tornado.web.RequestHandler):
        def get(self):
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.set_header("Cache-Control", "no-store")
            self.write(LIVE_PAGE)

    class Hold(tornado.web.RequestHandler):
        async def get(self):          # the page ends it when the scene is there; else it ends after HOLD_S
            self.set_header("Cache-Control", "no-store")
            await tornado.gen.sleep(HOLD_S)
            try:
                await self.finish()
            except tornado.iostream.StreamClosedError:
                pass

        def on_connection_close(self):
            pass

    scene_sent = umsgpack.packb({"type": SCENE_SENT})

    class Bridge(ZMQWebSocketBridge):
        def send_scene(self, websocket):
            super().send_scene(websocket)
            websocket.write_message(scene_sent, binary=True)

        def make_app(self):
            app = super().make_app()
            app.add_handlers(r".*", [(r"/live/hold", Hold), (r"/live/?", LivePage)])
            listen = app.listen
            app.listen = lambda port, **kw: listen(port, address=self.host, **kw)
            return app

    return Bridge


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="viz.bridge", description=__doc__)
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

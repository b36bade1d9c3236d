"""Viewer with a live meshcat server (no browser): lifecycle, errors, and what the scene holds, read
back from the server's self-contained page (each command is a base64 msgpack blob)."""
from __future__ import annotations

import base64
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from arm_model import ball_centres
from conftest import ROOT, assert_close
from viz import MeshcatServer, View, ViewerError, show, show_residuals


def page_commands(page: str) -> list[dict]:
    """The meshcat commands embedded in a static page, in order."""
    import umsgpack

    blobs = re.findall(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"\)', page)
    return [umsgpack.unpackb(base64.b64decode(b)) for b in blobs]


def transforms(cmds) -> dict[str, np.ndarray]:
    return {c["path"]: np.array(c["matrix"]).reshape(4, 4).T for c in cmds if c["type"] == "set_transform"}


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is gone for our purposes
    with open(f"/proc/{pid}/stat") as fh:
        return fh.read().split(") ", 1)[1][0] != "Z"


def wait_gone(pid: int, seconds: float = 5.0) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if not alive(pid):
            return True
        time.sleep(0.05)
    return False


def bridge_children(pid: int) -> list[int]:
    """Server processes (viz.bridge) started by process ``pid``."""
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            with open(f"/proc/{child}/cmdline", "rb") as fh:
                if b"viz.bridge" in fh.read().split(b"\0"):
                    out.append(int(child))
    return out


@pytest.fixture(autouse=True, scope="module")
def no_server_left():
    """After the module, this test process has no server process left."""
    yield
    assert bridge_children(os.getpid()) == []


def listeners(port: int) -> set[str]:
    """Local addresses (hex, as in /proc/net/tcp*) listening on ``port``."""
    found = set()
    for proto in ("tcp", "tcp6"):
        with open(f"/proc/net/{proto}") as fh:
            for line in fh.readlines()[1:]:
                local, state = line.split()[1], line.split()[3]
                addr, p = local.split(":")
                if state == "0A" and int(p, 16) == port:
                    found.add(f"{proto} {addr}")
    return found


Q = np.radians([0, 30, 0, 60, 0, 45, 0])
W = np.array([8.0, -2.0, 3.0])


def test_server_lifecycle_and_loopback_only():
    with MeshcatServer() as server:
        pid = server.pid
        assert server.running and server.url.startswith("http://127.0.0.1:") and server.url.endswith("/static/")
        with socket.create_connection(("127.0.0.1", server.port), timeout=5):
            pass
        assert listeners(server.port) == {"tcp 0100007F"}      # 127.0.0.1 only, not every interface
    assert not server.running and wait_gone(pid)
    server.close()                                        # idempotent


def test_busy_port_is_a_clear_error_and_leaves_nothing():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        server = MeshcatServer(port=port)
        with pytest.raises(ViewerError, match=f"port {port} on 127.0.0.1 is in use: choose another with --port"):
            server.start()
        assert server.pid is None and not server.running
    with pytest.raises(ViewerError, match="between 1 and 65535"):
        MeshcatServer(port=70000)


@pytest.mark.parametrize("ending", ["exit", "kill"])
def test_server_stops_with_its_parent(ending, tmp_path):
    """Normal exit (atexit) and SIGKILL of the parent (the server watches its parent) both stop it."""
    code = ("import os, sys, signal\n"
            "from viz import MeshcatServer\n"
            "s = MeshcatServer().start()\n"
            "print(s.pid, flush=True)\n"
            + ("os.kill(os.getpid(), signal.SIGKILL)\n" if ending == "kill" else "sys.exit(0)\n"))
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    pid = int(out.stdout.split()[0])
    assert wait_gone(pid, 5.0), f"server {pid} outlived its parent ({ending})"


def test_scene_holds_the_deflected_pose(nominal):
    """The drawn ball sits at the deflection-corrected centre (elastic joints set by statics), the arrow
    starts at the rigid centre and is scale x the deflection long, the legend says the scale."""
    with View(nominal) as view:
        info = view.show_pose(Q, W, scale=1000.0)
        page = view.html()
    rigid = ball_centres(nominal, Q[None])[0]
    corrected = ball_centres(nominal, Q[None], W[None])[0]
    assert_close(info.rigid, rigid, 1e-12)
    assert_close(info.corrected, corrected, 1e-12)
    assert 50e-6 < np.linalg.norm(corrected - rigid) < 200e-6
    tf = transforms(page_commands(page))
    assert_close(tf["/meshcat/aacmm/arm/visuals/ball_0"][:3, 3], corrected, 1e-12)
    arrow = tf["/meshcat/aacmm/deflection x1000"]
    assert_close(arrow[:3, 3], rigid, 1e-12)
    direction = arrow[:3, 1]
    assert_close(direction, (corrected - rigid) / np.linalg.norm(corrected - rigid), 1e-9)
    head = tf["/meshcat/aacmm/deflection x1000/head"]
    tip = head[1, 3] + head[1, 1] / 2
    assert tip == pytest.approx(1000 * np.linalg.norm(corrected - rigid), rel=1e-9)
    assert "<title>aacmm7: AACMM viewer</title>" in page
    assert "drawn x1000" in page


def test_zero_force_draws_the_rigid_arm(nominal):
    with View(nominal) as view:
        info = view.show_pose(Q, np.zeros(3))
        cmds = page_commands(view.html())
    assert_close(info.corrected, info.rigid, 0.0)
    head = transforms(cmds)["/meshcat/aacmm/deflection x1000/head"]
    assert head[1, 1] < 1e-8


def test_animation_is_embedded(nominal):
    qs = np.radians([[0, 30, 0, 60, 0, 45, 0], [20, 10, 0, 80, 0, 30, 0], [40, 0, 0, 90, 0, 10, 0]])
    ws = np.array([[5.0, 0, 0], [0, 5.0, 0], [0, 0, 5.0]])
    with View(nominal) as view:
        infos = view.animate(qs, ws, fps=4.0, repetitions=1)
        cmds = page_commands(view.html())
    anims = [c for c in cmds if c["type"] == "set_animation"]
    assert len(anims) == 1
    clips = {a["path"]: a["clip"] for a in anims[0]["animations"]}
    ball = clips["/meshcat/aacmm/arm/visuals/ball_0"]
    assert ball["fps"] == 4.0
    pos = next(t for t in ball["tracks"] if t["name"] == ".position")
    assert [k["time"] for k in pos["keys"]] == [0, 1, 2]
    assert_close([k["value"] for k in pos["keys"]], ball_centres(view.scene.desc, qs, ws), 1e-12)
    assert_close([i.corrected for i in infos], ball_centres(view.scene.desc, qs, ws), 1e-12)


def test_show_and_show_residuals_api(nominal):
    view = show(nominal, Q, wrench=W, scale=500)
    try:
        assert view.url.startswith("http://127.0.0.1:") and "drawn x500" in " ".join(view.legend)
        p = np.array([[0.5, 0.0, 0.3], [0.6, 0.1, 0.3]])
        r = np.array([[1e-6, 0, 0], [0, -2e-6, 0]])
        assert show_residuals(p, r, scale=2e4, view=view) is view
        cmds = page_commands(view.html())
        seg = next(c for c in cmds if c["type"] == "set_object"
                   and c["path"] == "/meshcat/aacmm/residuals x20000/vectors")
        assert seg["object"]["object"]["type"] == "LineSegments"
        assert "<iframe src=\"http://127.0.0.1:" in view._repr_html_()
    finally:
        view.close()
    assert not view.server.running
    # residuals alone, no arm
    with show_residuals(p, r) as alone:
        assert any("2 residual vector(s), drawn x1000" in line for line in alone.legend)


def test_docs_example_runs(tmp_path, monkeypatch, capsys):
    text = (ROOT / "docs" / "viewer.md").read_text()
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    exec(compile(code.replace('"urdf/aacmm7.dh.toml"', repr(str(ROOT / "urdf" / "aacmm7.dh.toml"))),
                 "docs/viewer.md", "exec"), {})
    out = capsys.readouterr().out
    assert out.startswith("http://127.0.0.1:") and "drawn x1000" in out
    page = (tmp_path / "pose.html").read_text()
    assert "2 residual vector(s), drawn x1000" in page


def test_a_server_that_stops_answering_is_a_clear_error(nominal):
    """A frozen server (SIGSTOP: its ports stay taken, so no other server can answer in its place)."""
    server = MeshcatServer().start()     # the default start-up wait: a loaded CI machine may need > 2 s
    server.timeout = 2.0                 # each reply from now on (the connected socket too): a 2 s wait
    try:
        with View(nominal, server=server) as view:
            os.kill(server.pid, signal.SIGSTOP)
            with pytest.raises(ViewerError, match="did not answer"):
                view.show_pose(Q, W)
    finally:
        os.kill(server.pid, signal.SIGCONT)
        server.close()


def test_a_server_that_died_is_a_clear_error(nominal):
    with View(nominal) as view:
        os.kill(view.server.pid, signal.SIGKILL)
        end = time.monotonic() + 5   # a zombie leader may wait for its threads before it can be reaped
        while view.server.running and time.monotonic() < end:
            time.sleep(0.02)
        with pytest.raises(ViewerError, match="has stopped"):
            view.show_pose(Q, W)


def test_a_robot_urdf_with_its_meshes_and_a_flange_tip(tmp_path):
    """A robot's URDF as it ships, its tip the flange (the last joint's own link: a rigid tip): the viewer
    draws the URDF's own mesh where it is found (missing ones left out), the ball at the tip; a mesh that
    cannot be loaded falls back to the generated links, saying so."""
    import trimesh

    from arm_model.urdf_import import load_arm
    text = (ROOT / "examples" / "data" / "real-panda-seats" / "panda.urdf").read_text()
    (tmp_path / "meshes").mkdir()
    (tmp_path / "robot").mkdir()
    trimesh.creation.box((0.05, 0.05, 0.2)).export(tmp_path / "meshes" / "link1.stl")
    urdf = tmp_path / "robot" / "panda.urdf"
    urdf.write_text(text.replace("../meshes/panda/link1.dae", "../meshes/link1.stl"))
    d = load_arm(urdf, "panda_link7")
    assert d.probe.lever == 0.0
    q = np.radians([0, 30, 0, -60, 0, 45, 0])
    with View(d) as view:
        info = view.show_pose(q)
        cmds = page_commands(view.html())
    assert_close(info.rigid, ball_centres(d, q[None])[0], 1e-12)
    meshes = [c["path"] for c in cmds if c["type"] == "set_object" and "geometries" in c["object"]
              and c["object"]["geometries"][0]["type"] == "_meshfile"]
    assert meshes == ["/meshcat/aacmm/arm/visuals/link_1_0"]
    assert any("its URDF's own visuals" in line for line in view.legend)
    (tmp_path / "meshes" / "link2.stl").write_text("not a mesh")
    urdf.write_text(text.replace("../meshes/panda/link1.dae", "../meshes/link1.stl")
                    .replace("../meshes/panda/link2.dae", "../meshes/link2.stl"))
    with View(load_arm(urdf, "panda_link7")) as view:
        info = view.show_pose(q)
    assert any("links orange" in line for line in view.legend)
    assert_close(info.rigid, ball_centres(d, q[None])[0], 1e-12)


def test_a_new_websocket_gets_the_scene_then_the_mark_the_live_page_waits_for():
    """The live page holds a request (/live/hold) open until the server's mark that the whole scene has been
    sent (viz.bridge.SCENE_SENT): a headless browser's virtual-time budget then cannot run out before the scene
    is there (it did when the server answered 0.2 s late). The mark comes after every command of the scene; the
    hold request is still open while the page waits; the page aborts it on the mark."""
    import asyncio

    import meshcat.geometry as mg
    import tornado.httpclient
    import tornado.websocket
    import umsgpack

    from viz.bridge import LIVE_PAGE, SCENE_SENT

    assert "/live/hold" in LIVE_PAGE and f'cmd.type === "{SCENE_SENT}"' in LIVE_PAGE and "hold.abort()" in LIVE_PAGE

    async def client(url):
        ws = await tornado.websocket.websocket_connect(url.rsplit("/static/", 1)[0].replace("http", "ws") + "/")
        types = []
        while not types or types[-1]["type"] != SCENE_SENT:
            types.append(umsgpack.unpackb(await asyncio.wait_for(ws.read_message(), 20)))
        ws.close()
        hold = tornado.httpclient.AsyncHTTPClient().fetch(url.rsplit("/static/", 1)[0] + "/live/hold",
                                                          request_timeout=0.3)
        try:
            await hold
            held = False
        except tornado.httpclient.HTTPClientError as exc:     # 599: our client gave up, the server still held it
            held = exc.code == 599
        return types, held

    with MeshcatServer() as server:
        server.visualizer["a"].set_object(mg.Box([0.1, 0.1, 0.1]))
        server.visualizer["b"].set_transform(np.eye(4))
        cmds, held = asyncio.run(client(server.url))
    assert [c["type"] for c in cmds][-1] == SCENE_SENT
    assert {"set_object", "set_transform"} <= {c["type"] for c in cmds[:-1]}
    assert SCENE_SENT not in [c["type"] for c in cmds[:-1]]
    assert held

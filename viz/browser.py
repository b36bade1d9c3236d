"""Headless Chromium: screenshots of a viewer page (a static file or the live server), and the pixel
test that tells whether the arm was drawn.

Chromium renders meshcat's WebGL without a GPU through SwiftShader. Each run gets a fresh profile
directory, no background networking, and a virtual-time budget so that the page settles quickly.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from arm_model.urdf import ARM_RGBA

from .errors import ViewerError

__all__ = ["find_chromium", "screenshot", "screenshot_and_dom", "load_png", "colour_mask", "arm_mask", "CHROMIUM_NAMES"]

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
          "--disable-background-networking", "--disable-component-update", "--disable-sync",
          "--no-first-run", "--no-default-browser-check", "--hide-scrollbars", "--mute-audio")


def find_chromium(browser: str | Path | None = None) -> str:
    """Path of the Chromium to use: ``browser`` if given (a path or a command name), else the first of
    :data:`CHROMIUM_NAMES` on PATH. Raises :class:`ViewerError` saying how to get one."""
    if browser is not None:
        found = shutil.which(str(browser))
        if found is None:
            raise ViewerError(f"no browser at '{browser}': give the path of a Chromium executable "
                              "(Debian: /usr/bin/chromium)")
        return found
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    raise ViewerError("no Chromium browser found (looked for " + ", ".join(CHROMIUM_NAMES) + " on PATH): "
                      "install Debian's 'chromium' package (`make browser` does it as root) or give its path")


def screenshot(page: str | Path, out_png: str | Path, *, width: int = 800, height: int = 600,
               budget_ms: int = 5000, browser: str | Path | None = None, timeout: float = 90.0) -> Path:
    """Render ``page`` (a file path, or an ``http://`` URL) in headless Chromium and write a PNG.

    Args:
        page: HTML file or URL.
        out_png: PNG to write (atomically: nothing is left on failure).
        width, height: window size [px].
        budget_ms: virtual time the page gets before the screenshot [ms].
        browser: Chromium to use (see :func:`find_chromium`).
        timeout: wall-clock limit [s].
    """
    return _chromium(page, out_png, width, height, budget_ms, browser, timeout, False)[0]


def screenshot_and_dom(page: str | Path, out_png: str | Path, *, width: int = 800, height: int = 600,
                       budget_ms: int = 5000, browser: str | Path | None = None,
                       timeout: float = 90.0) -> tuple[Path, str]:
    """:func:`screenshot`, and the page's document (HTML) as the browser had it then, from one run."""
    return _chromium(page, out_png, width, height, budget_ms, browser, timeout, True)


def _chromium(page, out_png, width, height, budget_ms, browser, timeout, dom: bool) -> tuple[Path, str]:
    exe = find_chromium(browser)
    page_s = str(page)
    if "://" not in page_s:
        path = Path(page_s)
        if not path.is_file():
            raise ViewerError(f"{page_s}: no such page to render")
        page_s = path.resolve().as_uri()
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="aacmm-chromium-") as profile:
        shot = Path(profile) / "shot.png"
        cmd = [exe, *_FLAGS, f"--user-data-dir={profile}/profile", f"--window-size={width},{height}",
               f"--virtual-time-budget={int(budget_ms)}", f"--screenshot={shot}", *(["--dump-dom"] if dom else []),
               page_s]
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                                start_new_session=True)
        try:
            out, err = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise ViewerError(f"Chromium did not render {page_s} within {timeout:g} s") from None
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        if proc.returncode != 0 or not shot.is_file() or shot.stat().st_size == 0:
            tail = " | ".join(err.decode("utf-8", "replace").strip().splitlines()[-3:])
            raise ViewerError(f"Chromium ({exe}) failed to render {page_s} (exit code {proc.returncode}): {tail}")
        tmp = out_png.with_name(f".{out_png.name}.tmp")
        shutil.copyfile(shot, tmp)
        os.replace(tmp, out_png)
    return out_png, out.decode("utf-8", "replace")


def load_png(path: str | Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB pixels of a PNG."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"))


def colour_mask(rgb: np.ndarray, rgba, hue_tol_deg: float = 8.0, min_saturation: float = 0.5,
                min_value: float = 0.3) -> np.ndarray:
    """(H, W) True where a pixel has the hue of ``rgba`` (within ``hue_tol_deg``) and is saturated and
    bright enough: a shaded surface of that colour, whatever its lighting."""
    import matplotlib.colors as mc

    hsv = mc.rgb_to_hsv(np.asarray(rgb, dtype=float)[..., :3] / 255.0)
    target = mc.rgb_to_hsv(np.asarray(rgba, dtype=float)[:3])
    dh = np.abs(hsv[..., 0] - target[0]) * 360.0
    dh = np.minimum(dh, 360.0 - dh)
    return (dh <= hue_tol_deg) & (hsv[..., 1] >= min_saturation) & (hsv[..., 2] >= min_value)


def arm_mask(rgb: np.ndarray) -> np.ndarray:
    """(H, W) True where a pixel shows an arm link (the URDF's orange ``ARM_RGBA``)."""
    return colour_mask(rgb, ARM_RGBA)

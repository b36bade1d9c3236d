"""The viewer's error: a server, a browser or a page that cannot do what was asked."""
from __future__ import annotations

from arm_model import AacmmError

__all__ = ["ViewerError"]


class ViewerError(AacmmError):
    """The meshcat server or the browser failed (port in use, no browser, server gone); the message
    says what to do."""

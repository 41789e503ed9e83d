"""The recorder's live view feed: messages in, the view's frames out to the MCAP (always:
a replay looks as live did) and to the WebSocket server when there is one.

A failure of the view is logged once and counted (`errors`), never raised: the view must
not cost the recording.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from deploy.recording.live_server import LiveServer
from deploy.recording.mcap_log import McapLog, RawFrame
from deploy.recording.view import LiveView
from transport.messages import Message

log = logging.getLogger(__name__)


class ViewFeed:
    """`view` None: no view at all (scene_hz None); `live` None: frames to the MCAP only."""

    def __init__(self, mcap: McapLog, view: LiveView | None, live: LiveServer | None) -> None:
        self.mcap, self.view, self.live = mcap, view, live
        self.errors = 0

    def add(self, msg: Message, recv_stamp_s: float) -> None:
        if self.view is None:
            return
        try:
            self.view.add(msg, recv_stamp_s)
        except Exception:
            self._failed()

    def show_new(self) -> None:
        """The frames of what was added since the last call."""
        if self.view is not None:
            self._show(self.view.frames)

    def tick(self, now_s: float, members: frozenset[int] | None) -> None:
        """The once-a-period frames (links, status)."""
        view = self.view
        if view is not None:
            self._show(lambda: view.tick_frames(now_s, members))

    def stop(self) -> None:
        if self.live is not None:
            self.live.stop()

    @property
    def url(self) -> str | None:
        return None if self.live is None else self.live.url

    @property
    def frames_sent(self) -> int:
        return 0 if self.live is None else self.live.frames_sent

    def _show(self, make: Callable[[], list[RawFrame]]) -> None:
        try:
            frames = make()
        except Exception:
            self._failed()
            return
        for frame in frames:
            self.mcap.write_raw(frame)
            if self.live is not None:
                self.live.publish(frame)

    def _failed(self) -> None:
        if not self.errors:
            log.exception("live view failed (counted in view_errors; recording goes on)")
        self.errors += 1

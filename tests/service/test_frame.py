"""A frame is encoded once per step and subscription; each client's copy carries its own
``dropped`` count (one message is shared by the clients whose counts agree)."""

from __future__ import annotations

from diathermy.service.encoding import unpack
from diathermy.service.hub import Frame


def test_each_client_gets_its_dropped_count_and_the_shared_pairs() -> None:
    message = {"type": "frame", "session": "s", "step": 7, "time_s": 0.21, "control_id": 2}
    frame = Frame.encode(message)
    for dropped in (0, 0, 3, 0, 70000, 70000):
        assert unpack(frame.to_bytes(dropped)) == {"dropped": dropped, **message}
    assert frame.to_bytes(5) is frame.to_bytes(5)  # built once for clients that agree

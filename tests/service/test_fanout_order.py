"""Fan-out order: the client whose electrode control a frame first shows gets it written first,
and the senders are woken a few hundred kB of frames per turn of the event loop, so that the loop
reads the sockets (a control, an ack to send) between two clients' writes of a large frame, while
small frames go out to every client in one turn."""

from __future__ import annotations

import asyncio

from diathermy.service.hub import TURN_BYTES, Frame, FrameSlot, StreamHub, Subscriber, Subscription


def _frame(control_id: int, nbytes: int = TURN_BYTES) -> Frame:
    """A frame of about ``nbytes`` (default: one turn's worth, so one client per turn)."""
    message = {"type": "frame", "step": 3, "control_id": control_id, "fields": b"x" * nbytes}
    return Frame.encode(message)


def _run_senders(awaiting: list[int], control_id: int, nbytes: int = TURN_BYTES) -> list[str]:
    """Deliver one frame to subscribers with the given ``awaiting`` ids; the order of events
    (``sN``: sender N woke; ``after-N``: a callback sender N scheduled when it woke)."""
    loop = asyncio.new_event_loop()
    try:
        hub = StreamHub()
        subs = [Subscriber(slot=FrameSlot(loop), awaiting=a) for a in awaiting]
        for sub in subs:
            hub.add(sub)
        order: list[str] = []

        async def sender(i: int, sub: Subscriber) -> None:
            frame = await sub.slot.get()
            assert frame.control_id == control_id
            order.append(f"s{i}")
            loop.call_soon(order.append, f"after-{i}")

        async def main() -> None:
            tasks = [asyncio.ensure_future(sender(i, s)) for i, s in enumerate(subs)]
            await asyncio.sleep(0)  # every sender waits on its slot
            assert hub.deliver({Subscription(): _frame(control_id, nbytes)}) == 0
            await asyncio.gather(*tasks)
            await asyncio.sleep(0)

        loop.run_until_complete(main())
        return order
    finally:
        loop.close()


def test_the_client_whose_control_the_frame_first_shows_is_written_first() -> None:
    # client 2 waits for control 5, which this frame shows; client 1 waits for a later one (7)
    order = [e for e in _run_senders([0, 7, 5, 0], control_id=5) if e.startswith("s")]
    assert order == ["s2", "s0", "s1", "s3"]


def test_senders_of_large_frames_are_woken_one_per_turn_of_the_event_loop() -> None:
    order = _run_senders([0, 0, 0], control_id=1)
    # what sender 0 scheduled runs before sender 1 wakes: the loop turned (and polled) between
    assert order.index("after-0") < order.index("s1")
    assert order.index("after-1") < order.index("s2")


def test_small_frames_go_to_every_client_in_one_turn() -> None:
    # a top face of a few kB: sixteen writes cost less than sixteen polls of the sockets
    order = _run_senders([0] * 16, control_id=1, nbytes=6_000)
    assert order[:16] == [f"s{i}" for i in range(16)]
    # a turn holds about TURN_BYTES: three frames of 0.4 x that go out two and one
    order = _run_senders([0, 0, 0], control_id=1, nbytes=int(0.4 * TURN_BYTES))
    assert order.index("s1") < order.index("after-0") < order.index("s2")


def test_a_frame_showing_the_control_clears_the_wait() -> None:
    sub = Subscriber(slot=FrameSlot(asyncio.new_event_loop()), awaiting=4)
    assert not sub.first_shown_by(_frame(3))
    assert sub.first_shown_by(_frame(4)) and sub.first_shown_by(_frame(9))
    assert not Subscriber(slot=sub.slot).first_shown_by(_frame(9))  # no control: no priority
    sub.slot.loop.close()


def test_the_clients_a_frame_first_shows_a_control_of_are_written_together_first() -> None:
    order = _run_senders([3, 0, 2, 0], control_id=3)
    assert order[:2] == ["s0", "s2"]  # both woken in one turn, before anything else runs
    assert order.index("after-0") < order.index("s1") < order.index("after-1") < order.index("s3")

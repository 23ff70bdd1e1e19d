"""The server reads the engine's replies with its own reader (one reused buffer): every size
of message, in order, and a clear EOFError when the engine's end closes."""

from __future__ import annotations

import multiprocessing
import threading

import pytest

from diathermy.service.engine_process import ReplyReader


def test_reads_what_connection_send_wrote_small_large_and_huge() -> None:
    ours, theirs = multiprocessing.Pipe()
    reader = ReplyReader(ours)
    messages = [
        (1, True, {"a": 1.5}, None),
        (2, True, b"x" * 1_200_000, None),  # a frame of the default grid
        (3, False, ValueError("boom"), None),
        (4, True, bytes(range(256)) * 40_000, None),  # over the kept buffer's 8 MB
        (5, True, b"y" * 20_000, None),  # back to a kept buffer
    ]
    sender = threading.Thread(target=lambda: [theirs.send(m) for m in messages])
    sender.start()
    got = [reader.recv() for _ in messages]
    sender.join()
    for sent, received in zip(messages, got, strict=True):
        assert received[:2] == sent[:2]
        if isinstance(sent[2], Exception):
            assert isinstance(received[2], ValueError) and str(received[2]) == "boom"
        else:
            assert received[2] == sent[2]
    assert ours.poll(0) is False  # nothing read ahead: poll on the pipe stays right
    theirs.close()
    with pytest.raises(EOFError):
        reader.recv()
    reader.close()
    ours.close()

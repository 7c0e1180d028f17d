"""Block transfer state machines: flow control, a lost frame resent, give-up rules."""

from __future__ import annotations

import pytest

from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState, frame_count
from robot_agent.robocan.protocol import MAX_BLOCK, EndStatus, Op, ProtocolError


def transfer(data: bytes, drop: set[int] | None = None) -> tuple[BlockSender, BlockReceiver]:
    """Run a transfer to its end, losing the data frames whose sequence numbers are in drop
    (each only the first time it is sent)."""
    drop = set(drop or ())
    sender = BlockSender(0x02, data)
    receiver = BlockReceiver(sender.start())
    replies = [receiver.first_reply()]
    for _ in range(1000):
        if not replies:
            replies = receiver.on_timeout()  # the receiver's time-out fired
        if not replies:
            break
        outgoing: list[bytes] = []
        for reply in replies:
            outgoing += sender.on_frame(reply)
        replies = []
        for frame in outgoing:
            if frame[1] in drop:
                drop.discard(frame[1])
                continue
            replies += receiver.on_data(frame)
        if sender.state is not BlockState.ACTIVE:
            break
    return sender, receiver


def test_block_arrives_whole_with_flow_control() -> None:
    data = bytes(range(200))
    sender, receiver = transfer(data)
    assert frame_count(200) == 33
    assert sender.state is BlockState.DONE and receiver.data == data


def test_lost_frame_is_asked_for_again_and_the_block_is_intact() -> None:
    data = bytes(range(100))
    sender, receiver = transfer(data, drop={3, 9})
    assert sender.state is BlockState.DONE and receiver.data == data
    assert receiver.retries == 2


def test_lost_last_frame_recovered_by_the_time_out() -> None:
    data = bytes(range(40))
    last = frame_count(len(data))
    sender, receiver = transfer(data, drop={last})
    assert receiver.data == data and sender.state is BlockState.DONE


def test_too_many_losses_abort_the_block() -> None:
    sender = BlockSender(0x02, bytes(60))
    receiver = BlockReceiver(sender.start())
    sender.on_frame(receiver.first_reply())
    for _ in range(4):
        replies = receiver.on_timeout()
    assert replies[0][0] == Op.BLOCK_END and replies[0][1] == EndStatus.TIMEOUT
    assert receiver.state is BlockState.FAILED
    sender.on_frame(replies[0])
    assert sender.state is BlockState.FAILED


def test_too_long_blocks_are_refused_on_both_sides() -> None:
    with pytest.raises(ProtocolError):
        BlockSender(0x02, bytes(MAX_BLOCK + 1))
    start = bytes([Op.BLOCK_START, 2, 0xFF, 0xFF, 0, 0, 0, 0])
    receiver = BlockReceiver(start)
    assert receiver.first_reply() == bytes([Op.BLOCK_END, EndStatus.TOO_LONG, 2])


def test_re_requests_count_per_block_not_per_gap() -> None:
    """Three re-requests in one block, whatever their cause; the fourth gap ends it."""
    sender = BlockSender(0x02, bytes(200))
    receiver = BlockReceiver(sender.start())
    frames = sender.on_frame(receiver.first_reply())
    replies: list[bytes] = []
    for gap in (2, 4, 6, 8):  # four separate gaps, each frame lost once
        frames = [f for f in frames if f[1] != gap]
        replies = []
        for frame in frames:
            replies += receiver.on_data(frame)
        frames = [f for r in replies for f in sender.on_frame(r)]
        if receiver.state is not BlockState.ACTIVE:
            break
    assert receiver.retries == 4 and receiver.state is BlockState.FAILED
    assert replies[-1] == bytes([Op.BLOCK_END, EndStatus.SEQUENCE, 0x02])


def test_an_empty_block_and_a_refused_block_end_at_once() -> None:
    empty = BlockSender(0x02, b"")
    assert len(empty.start()) == 4
    receiver = BlockReceiver(empty.start())
    assert receiver.first_reply() == bytes([Op.BLOCK_END, EndStatus.OK, 0x02])
    assert receiver.state is BlockState.DONE and receiver.data == b""
    # content judged once the block is whole: REFUSED instead of OK, and nothing kept
    sender = BlockSender(0x02, bytes(30))
    receiver = BlockReceiver(sender.start(), accept=lambda kind, data: data[0] != 0)
    replies = [receiver.first_reply()]
    while receiver.state is BlockState.ACTIVE:
        replies = [r for f in sender.on_frame(replies[-1]) for r in receiver.on_data(f)] or replies
    assert replies[-1] == bytes([Op.BLOCK_END, EndStatus.REFUSED, 0x02])
    sender.on_frame(replies[-1])
    assert sender.state is BlockState.FAILED and sender.end_status is EndStatus.REFUSED

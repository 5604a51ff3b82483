"""The re-ordering buffer: a context message (integrity verdict, J/S) of an instant leaves before
the measurements of the same stamp, whatever the order they arrived in."""

from dataclasses import dataclass

from uwb_gnss_fusion.reorder_buffer import ReorderBuffer


@dataclass
class Msg:
    stamp_ns: int
    name: str


def test_context_leaves_first_at_equal_stamps_and_arrival_order_holds_otherwise():
    buf = ReorderBuffer(window_ns=50)
    buf.push(Msg(100, 'epoch 100'))
    buf.push(Msg(100, 'range 100'))
    buf.push(Msg(90, 'range 90'))
    buf.push(Msg(100, 'verdict 100'), context=True)  # computed from epoch 100, so it arrives after it
    buf.push(Msg(120, 'verdict 120'), context=True)
    buf.push(Msg(120, 'epoch 120'))
    assert [m.name for m in buf.pop_ready(now_ns=170)] == [
        'range 90', 'verdict 100', 'epoch 100', 'range 100', 'verdict 120', 'epoch 120']


def test_a_context_message_older_than_a_released_one_is_late():
    buf = ReorderBuffer(window_ns=0)
    buf.push(Msg(100, 'epoch'))
    assert [m.name for m in buf.pop_ready(now_ns=100)] == ['epoch']
    assert not buf.push(Msg(99, 'verdict'), context=True) and buf.late == 1
    assert buf.push(Msg(100, 'verdict'), context=True)  # same stamp as the last released: still in time

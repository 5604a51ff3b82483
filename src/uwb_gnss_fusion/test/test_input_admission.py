"""The fusion node's admission and re-ordering state machine (input_admission.InputAdmission), without ROS:
duplicates, stamps, the re-ordering window and its growth, restarts after a confirmed stamp jump, flushes."""

from __future__ import annotations

from uwb_gnss_fusion.input_admission import InputAdmission, Item, jammer_rejection_text

S = 1_000_000_000


class Recorder:
    """An admission whose released items, restarts and warnings are recorded."""

    def __init__(self, window_s: float = 0.1, window_max_s: float = 1.0, confirmations: int = 3) -> None:
        self.released: list[tuple[str, int]] = []
        self.log: list[tuple[str, str]] = []
        self.restarts = 0
        self.before_release = 0
        self.admission = InputAdmission(window_s, window_max_s, 120.0, confirmations,
                                        lambda item: self.released.append((item.kind, item.stamp_ns)),
                                        self._restart, lambda text, level: self.log.append((level, text)),
                                        self._before)

    def _restart(self) -> None:
        self.restarts += 1
        self.released.append(('restart', 0))

    def _before(self) -> None:
        self.before_release += 1

    def offer(self, kind: str, stamp_s: float, key: tuple[str, int, str] | None = None) -> bool:
        return self.admission.offer(Item(round(stamp_s * S), kind, None), key)


def test_items_leave_in_stamp_order_once_the_window_has_passed_context_first():
    r = Recorder(window_s=0.1)
    r.offer('uwb', 1.00)
    r.offer('gnss', 1.05)
    r.offer('integrity', 1.05)  # the verdict of the epoch arrives after it, leaves before it
    r.offer('uwb', 1.02)  # late by 0.03 s: within the window
    assert r.released == [] and r.admission.buffered == {'gnss': 1, 'uwb': 2, 'jammer': 0, 'integrity': 1}
    r.offer('uwb', 1.20)
    assert r.released == [('uwb', 1 * S), ('uwb', round(1.02 * S)), ('integrity', round(1.05 * S)),
                          ('gnss', round(1.05 * S))]
    assert r.before_release == 5  # at every accepted item, before anything is released
    assert r.admission.flush('end_of_input_flushes') == 1 and r.released[-1] == ('uwb', round(1.2 * S))
    assert r.admission.counts['end_of_input_flushes'] == 1
    assert r.admission.flush('end_of_input_flushes') == 0 and r.admission.counts['end_of_input_flushes'] == 1


def test_duplicates_and_unset_stamps_are_rejected_and_counted():
    r = Recorder()
    assert r.offer('gnss', 1.0, ('gnss', S, ''))
    assert not r.offer('gnss', 1.0, ('gnss', S, ''))
    assert r.admission.seen(('gnss', S, '')) and not r.admission.seen(('uwb', S, 'a'))
    assert not r.offer('uwb', 0.0)
    assert r.admission.counts['gnss_rejected'] == 1 and r.admission.counts['uwb_rejected'] == 1
    assert r.admission.reasons == {'duplicate_gnss_epoch': 1, 'stamp_not_positive': 1}
    assert all(level == 'warn_throttled' for level, _ in r.log)


def test_a_late_item_is_rejected_and_widens_the_window_up_to_its_maximum():
    r = Recorder(window_s=0.1, window_max_s=1.0)
    r.offer('uwb', 10.0)
    r.offer('uwb', 10.5)  # releases 10.0
    assert not r.offer('uwb', 9.9)  # older than the released 10.0: 0.6 s late
    assert r.admission.reasons['late_beyond_reorder_window'] == 1
    assert abs(r.admission.reorder_window_s - 0.9) < 1e-9  # 1.5 x 0.6 s
    assert r.admission.counts['reorder_window_growths'] == 1
    r.offer('uwb', 20.0)  # releases 10.5
    assert not r.offer('uwb', 8.0)  # 12 s late: beyond any window, the window stays
    assert abs(r.admission.reorder_window_s - 0.9) < 1e-9 and r.admission.counts['reorder_window_growths'] == 1
    assert ('warn', 're-ordering window widened to 0.900 s (inputs arrive late; maximum reorder_window_max_s 1 s)') \
        in r.log


def test_a_confirmed_stamp_jump_processes_the_pending_items_then_restarts():
    r = Recorder(window_s=0.1, confirmations=3)
    r.offer('gnss', 1000.0)
    r.offer('uwb', 1000.05)
    assert not r.offer('uwb', 5000.0) and not r.offer('uwb', 5000.1)  # refused until the third agrees
    assert r.admission.reasons['stamp_far_future'] == 2
    assert r.offer('uwb', 5000.2)
    assert r.released == [('gnss', 1000 * S), ('uwb', round(1000.05 * S)), ('restart', 0)]
    assert r.restarts == 1 and r.admission.counts['time_jump_restarts'] == 1
    assert r.offer('uwb', 5000.19)  # the new time line: the buffer starts afresh (nothing released yet)
    assert r.admission.latest_ns == round(5000.2 * S)


def test_jammer_rejection_texts_name_the_value():
    assert 'type 9' in jammer_rejection_text('jammer_state_unknown_type', 9, 1.0)
    assert 'NaN' in jammer_rejection_text('jammer_state_nan', 1, float('nan'))
    assert '500.0 dB' in jammer_rejection_text('jammer_state_nonphysical', 1, 500.0)

"""The "vision too slow to hold" flag (issue 34 item 3: 69 on/off log lines in 9 minutes):
on at the first late detection, off only after VISION_RECOVERY_S of detections all in time, and
at most one warning a minute in the log."""

from __future__ import annotations

from skeye.pilot.vision import VISION_RECOVERY_S, LateVision, RateLimited


def test_one_late_detection_turns_it_on_and_a_flicker_never_turns_it_off() -> None:
    flag = LateVision()
    changes = []
    for i in range(100):  # 30 fps for 3.3 s, every third detection late
        change = flag.update(late=i % 3 == 0, now_s=i / 30)
        if change is not None:
            changes.append((i, change))
    assert changes == [(0, True)] and flag.on


def test_it_turns_off_after_the_recovery_time_of_detections_in_time() -> None:
    flag = LateVision()
    assert flag.update(True, 0.0) is True
    t = 0.0
    offs = []
    while t < 3.0:
        t += 0.1
        if flag.update(False, round(t, 9)) is False:
            offs.append(round(t, 9))
    # in time from 0.1 s on: off once VISION_RECOVERY_S of them has passed, and only once
    assert offs == [round(0.1 + VISION_RECOVERY_S, 9)] and not flag.on
    assert flag.update(True, 3.1) is True  # and on again at the next late one


def test_warnings_are_rate_limited_and_count_what_they_held_back() -> None:
    now = [0.0]
    say = RateLimited(60.0, clock=lambda: now[0])
    said = []
    for i in range(69):  # the newcomer's 9 minutes: a change every 7.8 s
        now[0] = i * 7.8
        if (text := say.say("too slow")) is not None:
            said.append(text)
    assert len(said) == 9, said  # one a minute
    assert said[0] == "too slow" and said[1] == "too slow (7 more such in the last 62 s)"


def test_a_clock_that_goes_back_counts_the_recovery_from_its_own_time() -> None:
    # Too slow, recovering since 500 s of the old clock; then the clock starts again (a
    # restarted simulator under a re-attached pilot): in time for VISION_RECOVERY_S of the new
    # clock turns it off, not only once the new clock passes 500 s.
    flag = LateVision()
    assert flag.update(True, 499.9) is True
    assert flag.update(False, 500.0) is None
    t, off_at = 0.0, None
    while t < 3.0 and off_at is None:
        if flag.update(False, round(t, 9)) is False:
            off_at = round(t, 9)
        t += 0.1
    assert off_at == round(VISION_RECOVERY_S, 9) and not flag.on

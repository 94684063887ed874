"""zswarm.util.progress: one progress style for sim, sweep and basin."""

from __future__ import annotations

import io

from zswarm.util.progress import WIDTH, Progress, hms


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_one_line_redrawn_in_place_and_messages_above_it():
    out = Tty()
    p = Progress(10, "runs", stream=out)
    p.update(3, extra="1 failed")
    p.line("run 3: failed")
    p.update(10)
    p.close()
    text = out.getvalue()
    assert text.endswith("\n") and text.count("\n") == 2  # the message's line, and the end
    parts = text.split("\r\x1b[K")[1:]  # the bar, the message, the bar redrawn below it, the bar at the end
    first, message, last = parts[0], parts[1], parts[-1]
    assert len(parts) == 4 and parts[2] == first
    assert first.startswith(f"[{'#' * (3 * WIDTH // 10)}{'-' * (WIDTH - 3 * WIDTH // 10)}] 3/10 runs, 1 failed, 0:00 elapsed")
    assert message == "run 3: failed\n"
    assert last.startswith(f"[{'#' * WIDTH}] 10/10 runs, 1 failed") and "left" not in last


def test_a_log_gets_plain_lines_and_no_carriage_return():
    out = io.StringIO()
    p = Progress(40.0, "s of world time", stream=out, every_s=3600)
    for t in range(1, 40):
        p.update(float(t))  # within every_s: nothing
    assert out.getvalue() == ""
    p.line("running on 2 processes")
    p.update(40.0)  # the end: one line
    p.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue() and len(lines) == 2
    assert lines[0].startswith("running on 2 processes  [[") and lines[1].startswith(f"[{'#' * WIDTH}] 40/40 s of world time")


def test_a_resumed_count_estimates_the_time_left_from_this_commands_pace():
    p = Progress(100, "draws", already=50, stream=io.StringIO())
    assert "left" not in p.text()  # nothing done by this command yet: no estimate
    p.done = 60
    assert "left" in p.text() and "60/100 draws" in p.text()
    assert hms(61.4) == "1:01" and hms(float("nan")) == "?"

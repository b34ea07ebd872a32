"""Progress reports during a render, shared by the command line and the Blender engine: how
often a report is worth printing, the time left, and the samples a render took."""


class ProgressThrottle:
    """Whether to report now: always when `every_poll` (Blender's window); otherwise — a log
    (`gdmlt render`, `blender -b`, where every report is a line) — once per 10% or 10 s."""

    def __init__(self, every_poll: bool = False):
        self.every_poll = every_poll
        self.last_step, self.last_time = 0, 0.0

    def __call__(self, fraction: float, elapsed: float) -> bool:
        if self.every_poll:
            return True
        step = int(fraction * 10)
        if (step > self.last_step or elapsed - self.last_time >= 10.0) and 0 < fraction < 1:
            self.last_step, self.last_time = step, elapsed
            return True
        return False


def seconds_left(fraction: float, elapsed: float):
    """The time left, extrapolated from the work done so far once it is 2% done (else None)."""
    if not 0.02 <= fraction < 1.0 or elapsed <= 0:
        return None
    return elapsed * (1.0 - fraction) / fraction


def samples_per_pixel(stats: dict) -> str:
    """The samples per pixel of a finished render: "256", or "16–256" where adaptive sampling
    (or a time limit in the middle of a pass) left pixels with different counts."""
    lo, hi = stats.get("spp_min"), stats.get("spp_max", "?")
    return f"{lo}–{hi}" if lo is not None and lo != hi else f"{hi}"

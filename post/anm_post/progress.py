"""Progress on stderr for long anm-post commands (slice stacks, rdf, convergence, export, voxels)."""
from __future__ import annotations

import sys
import time
from typing import Callable


def stderr_progress(what: str) -> Callable[[int, int], None]:
    """A progress reporter printing `what: 37% (148/400), 12 s left` on stderr, in place on a
    terminal and as lines (every 10 %) otherwise."""
    start = time.perf_counter()
    tty = sys.stderr.isatty()
    state = {"last": -1}

    def report(done: int, total: int) -> None:
        pct = int(100 * done / max(1, total))
        step = pct if tty else pct // 10 * 10
        if step == state["last"] and done < total:
            return
        state["last"] = step
        el = time.perf_counter() - start
        left = el * (total - done) / done if done else 0.0
        text = f"{what}: {pct:3d}% ({done}/{total}), {el:.0f} s, about {left:.0f} s left"
        end = "\n" if (not tty or done >= total) else ""
        print(("\r" if tty else "") + text, end=end, file=sys.stderr, flush=True)

    return report

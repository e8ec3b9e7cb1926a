"""Progress a person can follow: stage lines, evaluations with the current E (and cost) and an ETA.

On a terminal the evaluations are one progress bar (tqdm); otherwise one plain line each, so a
log shows them too; nothing under --quiet but the estimate. Once the first evaluations have been timed, a run
predicted to take more than a minute says so, with its estimate (evaluations left x the median
time of an evaluation after the first of each kind, which includes compiling).
"""

from __future__ import annotations

import statistics
import sys
import time
from typing import Any, TextIO

from tqdm import tqdm

LONG_RUN_S = 60.0


class Progress:
    """`progress(message)` prints a stage line; `progress.evaluation(event)` counts one
    evaluation (`diffsense.optimise`'s `on_evaluation` hook)."""

    def __init__(self, quiet: bool, stream: TextIO | None = None):
        self.quiet, self.stream = quiet, sys.stderr if stream is None else stream  # stderr as it is now
        self.t0 = time.perf_counter()
        self._bar: Any = None
        self._times: list[float] = []
        self._kinds: set[str] = set()
        self._last = self.t0
        self._warned = False

    def __call__(self, message: str) -> None:
        if self.quiet:
            return
        self._close_bar()
        print(f"[{time.perf_counter() - self.t0:6.1f} s] {message}", file=self.stream, flush=True)

    def evaluation(self, event: dict[str, Any]) -> None:
        now = time.perf_counter()
        if event["kind"] in self._kinds:  # the first of each kind compiles: not a run time
            self._times.append(now - self._last)
        self._kinds.add(event["kind"])
        self._last = now
        done, planned = event["done"], max(event["planned"], event["done"])
        eta = statistics.median(self._times) * (planned - done) if self._times else None
        if eta is not None and eta > LONG_RUN_S and not self._warned:
            self._warned = True  # said even under --quiet: a long run should never be silent
            self._close_bar()
            print(f"[{now - self.t0:6.1f} s] estimate: {planned - done} evaluations left x "
                  f"{statistics.median(self._times):.1f} s = about {eta / 60:.1f} min", file=self.stream, flush=True)
        if self.quiet:
            return
        text = f"E {event['kind']} = {event['E_m']:.4f} m"
        if event.get("cost") is not None:  # a cost-aware (box) solve also says what the point costs
            text += f", cost {event['cost']:.2f}"
        text += f", ETA {eta:.0f} s" if eta is not None else ""
        if self.stream.isatty():
            if self._bar is None:
                self._bar = tqdm(total=planned, initial=done - 1, unit="eval", file=self.stream, dynamic_ncols=True)
            self._bar.total = planned
            self._bar.set_postfix_str(text, refresh=False)
            self._bar.update(1)
        else:
            print(f"[{now - self.t0:6.1f} s] evaluation {done}/{planned}: {text}", file=self.stream, flush=True)

    def _close_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

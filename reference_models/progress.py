"""Progress of long jobs: a tqdm bar on a terminal, a plain line every few seconds elsewhere.

Redirected to a file or a CI log, a bar's carriage-return redraws pile up into hundreds of kB;
there the same progress comes as one short line per `every` seconds and one when the job ends.
"""
from __future__ import annotations

import sys
import time

LINE_EVERY_S = 10.0


def progress_bar(total: int, desc: str, unit: str, enabled: bool = True, initial: int = 0, stream=None):
    """A progress object with update(n), set_postfix(**values) and close(): a tqdm bar when `stream`
    (default stderr) is a terminal, else a LineProgress; a Silent one unless enabled. tqdm is
    imported only for a bar."""
    stream = sys.stderr if stream is None else stream
    if not enabled:
        return Silent()
    if getattr(stream, "isatty", lambda: False)():
        from tqdm import tqdm

        return tqdm(total=total, initial=initial, desc=desc, unit=unit, file=stream)
    return LineProgress(total, desc, unit, initial, stream)


class Silent:
    """Progress that shows nothing."""

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix(self, **values) -> None:
        pass

    def close(self) -> None:
        pass


class LineProgress:
    """Prints "desc: done/total unit (percent, rate, postfix)" every LINE_EVERY_S seconds and at close."""

    def __init__(self, total: int, desc: str, unit: str, initial: int = 0, stream=None, every: float = LINE_EVERY_S):
        self.total, self.desc, self.unit, self.n = total, desc, unit, initial
        self.stream, self.every = stream or sys.stderr, every
        self.started = self.last = time.monotonic()
        self.start_n, self.postfix = initial, ""

    def update(self, n: int = 1) -> None:
        self.n += n
        if time.monotonic() - self.last >= self.every:
            self._print()

    def set_postfix(self, **values) -> None:
        self.postfix = ", ".join(f"{k}={v}" for k, v in values.items())

    def close(self) -> None:
        self._print()

    def _print(self) -> None:
        self.last = time.monotonic()
        elapsed = self.last - self.started
        rate = (self.n - self.start_n) / elapsed if elapsed > 0 else 0.0
        share = f"{100.0 * self.n / self.total:.0f}%, " if self.total else ""
        extra = f", {self.postfix}" if self.postfix else ""
        print(f"{self.desc}: {self.n}/{self.total} {self.unit} ({share}{rate:.3g} {self.unit}/s, "
              f"{elapsed:.0f} s{extra})", file=self.stream, flush=True)

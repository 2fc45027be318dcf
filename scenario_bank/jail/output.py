"""The captured output of a jailed process: only its tail is kept."""

from __future__ import annotations

import os
import threading

__all__ = ["OutputTail", "printable"]


class OutputTail:
    """Drains a pipe, keeping the last ``limit`` bytes and counting the rest."""

    def __init__(self, fd: int, limit: int) -> None:
        self.limit = limit
        self.data = bytearray()
        self.total = 0
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._drain, args=(fd,), daemon=True, name="dv2s-jail-output")
        self._thread.start()

    def _drain(self, fd: int) -> None:
        try:
            while True:
                chunk = os.read(fd, 65536)
                if not chunk:
                    break
                with self._lock:
                    self.total += len(chunk)
                    self.data += chunk
                    if len(self.data) > self.limit:
                        del self.data[: len(self.data) - self.limit]
        except OSError:
            pass
        finally:
            os.close(fd)

    def text(self) -> str:
        with self._lock:
            tail = self.data.decode("utf-8", "replace")
            dropped = self.total - len(self.data)
        tail = printable(tail)
        return (f"[... {dropped} earlier bytes dropped ...]\n" if dropped > 0 else "") + tail

    def join(self, timeout: float) -> None:
        self._thread.join(timeout)


def printable(text: str) -> str:
    """``text`` with every character a terminal would act on (escape sequences, bells, ...) shown as ``?``."""
    return "".join(c if c.isprintable() or c in "\n\t" else "?" for c in text)

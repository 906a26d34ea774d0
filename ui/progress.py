"""A one-line terminal progress bar (stderr), quiet when stderr is not a terminal."""
import sys
import time


class Progress:
    def __init__(self, total, label="frames", stream=None):
        self.total, self.label = total, label
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.start = time.perf_counter()
        self._last = 0.0
        self._open = False          # a bar is on the terminal's current line
        # A compile notice ends the bar's line first (cloth/compile_notice.py).
        from cloth import compile_notice
        compile_notice.before_print.append(self.end_line)

    def update(self, done, note=""):
        now = time.perf_counter()
        if not self.tty and done not in (self.total,) and now - self._last < 10.0:
            return
        self._last = now
        elapsed = now - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else 0.0
        width = 30
        fill = int(width * done / max(self.total, 1))
        line = (f"[{'#' * fill}{'.' * (width - fill)}] {done}/{self.total} {self.label}"
                f"  {rate:5.1f}/s  eta {f'{eta:5.0f}s' if rate > 0 else '    ?'}  {note}")
        if self.tty:
            self.stream.write("\r" + line[:120].ljust(120))
            self._open = True
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def end_line(self):
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False

    def close(self):
        from cloth import compile_notice
        if self.end_line in compile_notice.before_print:
            compile_notice.before_print.remove(self.end_line)
        self.end_line()

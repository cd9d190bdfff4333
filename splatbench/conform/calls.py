"""The backend side of `splatbench conform`: a backend's prints kept out of conform's output (`captured`).

Rendering a probe scene and taking its VJP, with every fault in one line, is the verification
core's (`splatbench.verification.calls`: `forward`, `vjp`, `Fault`)."""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile


class Captured:
    """What was written to stdout and stderr inside `captured` (``.text``, set on exit)."""

    text = ""


@contextlib.contextmanager
def captured():
    """Capture everything written to stdout and stderr, by Python or by native code (file descriptors
    1 and 2), so a backend's prints stay out of conform's table and JSON."""
    box = Captured()
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.redirect_stderr(io.StringIO()) as err:
                try:
                    yield box
                finally:
                    box.text = out.getvalue() + err.getvalue()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            box.text = sink.read().decode("utf-8", "replace") + box.text

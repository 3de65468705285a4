"""Helpers for tests that start Python child processes."""

from __future__ import annotations

import signal


def sigint_default() -> None:
    """``preexec_fn`` of a child: SIGINT back to its default action before exec, so that the
    child's Python installs KeyboardInterrupt. Python leaves SIGINT ignored when it starts with
    it ignored, as every background job of a non-interactive shell does (``make test &``, a CI
    runner's background step), and a test of Ctrl-C would then see nothing happen."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)

"""Ctrl-C and SIGTERM stop a command even when it inherited SIGINT ignored."""

from __future__ import annotations

import signal

import pytest

from deploy.procs.interrupts import interrupts

pytestmark = pytest.mark.timeout(30)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_interrupts_even_when_sigint_was_ignored(sig: signal.Signals) -> None:
    before = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(KeyboardInterrupt), interrupts():
            signal.raise_signal(sig)
            for _ in range(1000):  # the handler runs between bytecodes, on the main thread
                pass
        # and what was inherited is back after the block
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)

"""Test session set-up shared by tests/, docs/ and the doctests of src/.

A shell without job control starts background commands (``pytest ... &``, a CI runner's detached job)
with SIGINT ignored, and Python keeps it ignored.  kronlag rightly leaves a SIGINT handler it did not
install alone, so the tests of Ctrl-C (and the subprocesses they start, which inherit an ignored signal)
would see no interrupt; they test kronlag under Python's default handler, given back here.
"""

import signal


def pytest_configure(config):
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
